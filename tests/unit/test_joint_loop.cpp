// The joint optimization end to end (issue 7's acceptance): the gradient of the whole chain
// (lens variables -> rendered crops -> restoration loss) against central finite differences; a
// TorchScript task trained jointly through "torchscript:MODEL.pt"; resuming from a checkpoint
// reproduces the uninterrupted trajectory; glass variables always map to catalog glasses and
// every change is logged. Small images and sampling keep it to seconds.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <random>
#include <sstream>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/joint/joint.h"
#include "lensopt/lens/lens_io.h"
#include "test_joint_support.h"
#include "test_support.h"

namespace test_joint_loop {

using namespace lensopt;

namespace {

Lens doublet() {
  return read_lens(test::source_dir() / "lenses" / "doublet.toml");
}

JointOptions tiny_options(const std::filesystem::path& dir) {
  JointOptions o;
  o.data.builtin_scenes = 3;
  o.data.builtin_width = 160;
  o.data.builtin_height = 120;
  o.data.crop_px = 32;
  o.data.batch_size = 2;
  o.data.eval_crops = 2;
  o.imaging.sampling.rings = 4;
  o.imaging.sampling.fields = 5;
  o.design_sampling.rings = 4;
  o.design_sampling.fields = 3;
  o.task_options.features = 8;
  o.task_options.layers = 3;
  o.constant_steps = 3;
  o.decay_steps = 3;
  o.run_baselines = false;
  o.verbose = false;
  o.log_csv = dir / "log.csv";
  return o;
}

std::filesystem::path fresh_dir(const std::string& name) {
  const auto dir = test::joint_temp_dir(name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace

TEST_CASE("joint: glass variables always map to catalog glasses") {
  const Lens lens = doublet();
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const GlassSpace& space = param.glass_space();
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal(0.0, 1.5);
  std::vector<double> x = param.from_lens(lens);
  for (int trial = 0; trial < 200; ++trial) {
    for (int i = 0; i < param.size(); ++i)
      if (param.variables()[i].group == "glasses") x[i] = normal(rng);
    const TraceLens<double> tl = param.to_trace_lens(x.data(), GlassMode::kQuantized);
    const std::vector<int> nearest = param.nearest_glasses(x.data());
    int m = 0;
    for (std::size_t k = 0; k < tl.is_glass.size(); ++k) {
      if (!tl.is_glass[k]) continue;
      CHECK(tl.nd[k] == doctest::Approx(space.nd(nearest[m])).epsilon(1e-12));
      CHECK(tl.vd[k] == doctest::Approx(space.vd(nearest[m])).epsilon(1e-12));
      ++m;
    }
    const Lens out = param.to_lens(x.data(), GlassMode::kQuantized);
    for (const Surface& s : out.surfaces)
      if (!s.material.is_air()) CHECK(s.material.kind == Material::Kind::kCatalog);
  }
}

TEST_CASE("joint: the whole chain's gradient matches central finite differences") {
  // Lens variables -> PSFs, RI, distortion (Jets) -> rendered crops -> restoration loss of a
  // fixed network (float64) -> backward through the network and the imaging adjoint. The loss
  // is evaluated on the crops in double (render_values): float rounding (6e-8 per pixel) would
  // swamp differences at the step h = 1e-6 that central differences need here (truncation
  // ~h^2; joint/imaging's own test finds 2e-4 of it on the defocus at h = 1e-5).
  if (!torch_available()) return;
  const Lens lens = doublet();
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  DifferentiableImagingOptions io;
  io.sampling.rings = 6;
  io.sampling.fields = 5;
  // Continuous glasses: the quantized forward pass is piecewise constant in g, so finite
  // differences could not see the straight-through gradient.
  DifferentiableImaging imaging(param, GlassMode::kContinuous, {}, io);
  DataOptions d;
  d.builtin_scenes = 2;
  d.builtin_width = 240;
  d.builtin_height = 180;
  d.crop_px = 40;
  JointData data(d);
  const std::vector<Sample> samples = {{0, CropWindow{170, 110, 40, 40}},
                                       {1, CropWindow{20, 70, 40, 40}}};
  TaskOptions t;
  t.double_precision = true;
  t.features = 8;
  t.layers = 3;
  t.learning_rate = 1e-2;
  auto task = make_task("restoration", t);
  auto batch_at = [&](const std::vector<double>& x) {
    imaging.prepare(x);
    TaskBatch batch;
    for (const Sample& s : samples) {
      const FloatImage& scene = data.scenes()[s.scene].image;
      batch.rendered.push_back(imaging.render(scene, s.crop));
      batch.rendered_values.push_back(imaging.render_values(scene, s.crop));
      batch.sharp.push_back(data.crop(s));
      batch.targets.emplace_back();
    }
    return batch;
  };
  const std::vector<double> x = param.from_lens(lens);
  // A few training steps so the network is not the identity.
  const TaskBatch batch = batch_at(x);
  for (int i = 0; i < 5; ++i) task->step(batch, true, false);
  const TaskOutput out = task->step(batch, false, true);
  std::vector<double> grad;
  for (std::size_t b = 0; b < samples.size(); ++b)
    imaging.backward(data.scenes()[samples[b].scene].image, samples[b].crop, out.grad_rendered[b],
                     grad);
  REQUIRE(grad.size() == x.size());
  double worst = 0;
  for (int i = 0; i < param.size(); ++i) {
    const double h = 1e-6 * std::max(1.0, std::abs(x[i]));
    std::vector<double> xp = x, xm = x;
    xp[i] += h;
    xm[i] -= h;
    const double lp = task->step(batch_at(xp), false, false).loss;
    const double lm = task->step(batch_at(xm), false, false).loss;
    const double fd = (lp - lm) / (2 * h);
    const double rel = std::abs(grad[i] - fd) / std::max(std::abs(fd), 1e-300);
    worst = std::max(worst, rel);
    INFO(param.variables()[i].name, ": chain ", grad[i], " fd ", fd, " rel ", rel);
    CHECK(rel <= 1e-4);
  }
  MESSAGE("whole chain: worst relative error ", worst, " over ", param.size(), " variables");
}

TEST_CASE("joint: a TorchScript task trains jointly with the lens through torchscript:MODEL.pt") {
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_ts_loop");
  JointOptions o = tiny_options(dir);
  o.task = "torchscript:" + test::write_test_torchscript_module(dir).string();
  o.task_options.learning_rate = 1e-2;
  const JointResult r = optimize_joint(doublet(), o, dir / "net.pt");
  CHECK(!r.interrupted);
  CHECK(r.steps_done == 6);
  CHECK(std::filesystem::file_size(dir / "net.pt") > 0);
  const auto rows = test::csv_rows(dir / "log.csv");
  REQUIRE(rows.size() == 7);
  CHECK(rows[0][5] == "loss_task");
  CHECK(rows[0][13] == "grad_norm_task");
  const double first = std::stod(rows[1][5]), last = std::stod(rows[6][5]);
  CHECK(std::isfinite(first));
  CHECK(last < first);
  CHECK(std::stod(rows[1][13]) > 0);  // the task's loss reaches the lens
  const LensParameterization param(doublet(), GlassSpace(*load_catalog("ohara")));
  CHECK(r.x != param.from_lens(doublet()));
  REQUIRE(r.settings.size() == 1);
  CHECK(std::isfinite(r.settings[0].metric));
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint: resuming from a checkpoint gives the uninterrupted trajectory") {
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_resume");
  JointOptions o = tiny_options(dir);
  o.run_baselines = true;  // the checkpoint also carries the finished settings
  o.constant_steps = 2;
  o.decay_steps = 2;
  o.log_csv = dir / "straight.csv";
  const JointResult straight = optimize_joint(doublet(), o);
  // Interrupted after 6 of the 8 trained steps (4 fixed/trained + 2 joint), then resumed.
  o.log_csv = dir / "resumed.csv";
  o.checkpoint_every = 1;
  o.checkpoint_dir = dir / "ckpt";
  o.stop_after_steps = 6;
  const JointResult first = optimize_joint(doublet(), o);
  CHECK(first.interrupted);
  o.stop_after_steps = -1;
  o.resume_dir = dir / "ckpt";
  const JointResult resumed = optimize_joint(doublet(), o);
  CHECK(!resumed.interrupted);
  CHECK(read_file(dir / "resumed.csv") == read_file(dir / "straight.csv"));
  CHECK(resumed.x == straight.x);
  REQUIRE(resumed.settings.size() == 3);
  for (int i = 0; i < 3; ++i) CHECK(resumed.settings[i].metric == straight.settings[i].metric);
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint: every glass change is logged, and the log names catalog glasses only") {
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_glass");
  JointOptions o = tiny_options(dir);
  o.lens_learning_rate = 0.3;  // large steps: glasses change
  o.freeze = {"curvatures", "spacings"};
  const JointResult r = optimize_joint(doublet(), o);
  const GlassSpace space(*load_catalog("ohara"));
  const auto rows = test::csv_rows(dir / "log.csv");
  const std::size_t first_glass = 15;
  REQUIRE(rows[0].size() == first_glass + 2);
  int changes = 0;
  for (std::size_t i = 1; i < rows.size(); ++i) {
    for (std::size_t c = first_glass; c < rows[i].size(); ++c) {
      bool known = false;
      for (int g = 0; g < space.size(); ++g) known = known || space.name(g) == rows[i][c];
      CHECK(known);
      if (i > 1 && rows[i][c] != rows[i - 1][c]) ++changes;
    }
  }
  // The last step's change shows in the result, not in a later row.
  int final_changes = 0;
  for (std::size_t e = 0; e < r.glasses.size(); ++e)
    final_changes += r.glasses[e] != rows.back()[first_glass + e];
  CHECK(changes + final_changes == static_cast<int>(r.glass_changes.size()));
  CHECK(!r.glass_changes.empty());
  for (const Surface& s : r.lens.surfaces)
    if (!s.material.is_air()) CHECK(s.material.kind == Material::Kind::kCatalog);
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint: the learning rate is constant, then a half cosine to 0") {
  CHECK(learning_rate_factor(0, 10, 20) == 1.0);
  CHECK(learning_rate_factor(9, 10, 20) == 1.0);
  CHECK(learning_rate_factor(10, 10, 20) == 1.0);
  CHECK(learning_rate_factor(20, 10, 20) == doctest::Approx(0.5));
  CHECK(learning_rate_factor(30, 10, 20) == doctest::Approx(0.0));
  CHECK(learning_rate_factor(15, 10, 20) ==
        doctest::Approx(0.5 * (1 + std::cos(3.14159265358979323846 / 4))));
  CHECK(learning_rate_factor(50, 10, 0) == 1.0);
}

}  // namespace test_joint_loop
