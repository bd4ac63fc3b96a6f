// Robust long runs of the joint optimization (issue 13): a failed step (an exception, a
// non-finite loss) reverts the lens to before the last update, halves the lens step and the run
// goes on; too many failures in a row end it with the error. And the calls documented as
// concurrent (joint imaging's render/backward, Renderer::render) from two threads at once. The task
// here is a plain C++ one (no libtorch): the mean squared error of the rendered crops to the sharp
// ones, with no parameters of its own, so the lens alone moves.
#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <set>
#include <sstream>
#include <thread>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/glass/glass.h"
#include "lensopt/joint/imaging.h"
#include "lensopt/joint/joint.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/render.h"
#include "test_joint_support.h"
#include "test_support.h"

namespace test_joint_robust {

using namespace lensopt;

namespace {

// L = mean over pixels, channels and images of (R - S)^2; dL/dR = 2 (R - S) / (N B). Step
// number k (1-based) in `throw_at` throws, in `nan_at` returns a NaN loss.
class MseTask : public Task {
 public:
  MseTask(std::set<int> throw_at, std::set<int> nan_at)
      : throw_at_(std::move(throw_at)), nan_at_(std::move(nan_at)) {}
  std::string name() const override { return "mse"; }
  TaskOutput step(const TaskBatch& batch, bool, bool want_grad) override {
    ++calls_;
    if (throw_at_.count(calls_)) throw Error("injected failure");
    TaskOutput out;
    const double b = static_cast<double>(batch.rendered.size());
    for (std::size_t k = 0; k < batch.rendered.size(); ++k) {
      const FloatImage& r = batch.rendered[k];
      const FloatImage& s = batch.sharp[k];
      const double n = static_cast<double>(r.pixels.size());
      FloatImage g = r;
      for (std::size_t i = 0; i < r.pixels.size(); ++i) {
        const double d = static_cast<double>(r.pixels[i]) - s.pixels[i];
        out.loss += d * d / (n * b);
        g.pixels[i] = static_cast<float>(2.0 * d / (n * b));
      }
      if (want_grad) out.grad_rendered.push_back(std::move(g));
    }
    if (nan_at_.count(calls_)) out.loss = std::numeric_limits<double>::quiet_NaN();
    return out;
  }
  double metric(const TaskBatch& batch) override { return -step_loss(batch); }
  std::string metric_name() const override { return "-mse"; }
  void set_learning_rate(double) override {}
  std::vector<FloatImage> predict(const TaskBatch& batch) override { return batch.rendered; }
  void save(const std::filesystem::path& path) const override { write_file_atomic(path, "mse"); }
  void load(const std::filesystem::path&) override {}
  void save_network(const std::filesystem::path& path) const override {
    write_file_atomic(path, "mse");
  }

 private:
  double step_loss(const TaskBatch& batch) const {
    double loss = 0;
    for (std::size_t k = 0; k < batch.rendered.size(); ++k)
      for (std::size_t i = 0; i < batch.rendered[k].pixels.size(); ++i) {
        const double d =
            static_cast<double>(batch.rendered[k].pixels[i]) - batch.sharp[k].pixels[i];
        loss +=
            d * d / static_cast<double>(batch.rendered[k].pixels.size() * batch.rendered.size());
      }
    return loss;
  }
  std::set<int> throw_at_, nan_at_;
  int calls_ = 0;
};

JointOptions robust_options(const std::filesystem::path& dir, std::set<int> throw_at,
                            std::set<int> nan_at) {
  JointOptions o;
  o.data.builtin_scenes = 2;
  o.data.builtin_width = 160;
  o.data.builtin_height = 120;
  o.data.crop_px = 32;
  o.data.batch_size = 1;
  o.data.eval_crops = 1;
  o.imaging.sampling.rings = 4;
  o.imaging.sampling.fields = 5;
  o.design_sampling.rings = 4;
  o.design_sampling.fields = 3;
  o.design_sampling.threads = 1;  // l_lens reproducible to the last bit
  o.constant_steps = 6;
  o.decay_steps = 0;
  o.run_baselines = false;
  o.verbose = false;
  o.log_csv = dir / "log.csv";
  o.task_factory = [throw_at, nan_at](const std::string&, const TaskOptions&) {
    return std::make_unique<MseTask>(throw_at, nan_at);
  };
  return o;
}

}  // namespace

TEST_CASE("joint: a failed step is reverted with half the lens step, and the run goes on") {
  const auto dir = test::joint_temp_dir("lensopt_test_joint_robust");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  // Step t = 2 (the task's third call) throws, t = 4 returns a NaN loss.
  const JointOptions o = robust_options(dir, {3}, {5});
  const JointResult r = optimize_joint(lens, o);
  CHECK(!r.interrupted);
  CHECK(r.reverted_steps == 2);
  CHECK(r.steps_done == 6);
  REQUIRE(r.settings.size() == 1);
  CHECK(r.settings[0].done);
  CHECK(std::isfinite(r.settings[0].metric));
  for (double v : r.x) CHECK(std::isfinite(v));
  // The log holds the 4 steps that succeeded: 0, 1, 3, 5.
  const auto rows = test::csv_rows(o.log_csv);
  REQUIRE(rows.size() == 5);
  CHECK(rows[1][1] == "0");
  CHECK(rows[2][1] == "1");
  CHECK(rows[3][1] == "3");
  CHECK(rows[4][1] == "5");
  // Step 3 ran at the lens of step 1 (step 2's failure reverted step 1's update), so l_lens
  // (column 6) is the same to the last digit, with half the lens learning rate (column 2).
  CHECK(rows[3][6] == rows[2][6]);
  CHECK(std::stod(rows[2][2]) == doctest::Approx(o.lens_learning_rate));
  CHECK(std::stod(rows[3][2]) == doctest::Approx(0.5 * o.lens_learning_rate));
  // Step 3 succeeded (the step grows back to full), step 4's NaN reverted its update: step 5
  // ran at the lens of step 1 again, with half the step.
  CHECK(rows[4][6] == rows[2][6]);
  CHECK(std::stod(rows[4][2]) == doctest::Approx(0.5 * o.lens_learning_rate));
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint: too many failed steps in a row end the run with the error") {
  const auto dir = test::joint_temp_dir("lensopt_test_joint_failing");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  JointOptions o = robust_options(dir, {2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12}, {});
  o.constant_steps = 12;
  CHECK_THROWS_WITH_AS(optimize_joint(lens, o), doctest::Contains("failed steps in a row"), Error);
  std::filesystem::remove_all(dir);
}

TEST_CASE(
    "joint imaging: render and backward from two threads at once give the one-thread values") {
  // imaging.h allows render() and backward() from several threads at once (the ThreadSanitizer
  // run of docs/tsan.md watches this test for races on the kernels, caches and timings).
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  const std::vector<double> x = param.from_lens(lens);
  DifferentiableImagingOptions opt;
  opt.sampling.rings = 4;
  opt.sampling.fields = 5;
  opt.threads = 1;
  DifferentiableImaging imaging(param, GlassMode::kQuantized, {}, opt);
  imaging.prepare(x);
  FloatImage scene(160, 120, 3);
  for (std::size_t i = 0; i < scene.pixels.size(); ++i)
    scene.pixels[i] = static_cast<float>((i * 7919) % 101) / 100.0f;
  const CropWindow crops[2] = {{8, 8, 48, 40}, {100, 60, 48, 40}};
  FloatImage grad(48, 40, 3);
  for (std::size_t i = 0; i < grad.pixels.size(); ++i)
    grad.pixels[i] = static_cast<float>((i * 31) % 17) / 17.0f - 0.5f;
  std::vector<double> one[2], gx_one[2];
  for (int k = 0; k < 2; ++k) {
    one[k] = imaging.render_values(scene, crops[k]);
    imaging.backward(scene, crops[k], grad, gx_one[k]);
  }
  imaging.prepare(x);  // empties the kernels and the forward cache: the threads race to make them
  std::vector<double> two[2], gx_two[2];
  std::thread workers[2];
  for (int k = 0; k < 2; ++k)
    workers[k] = std::thread([&, k] {
      two[k] = imaging.render_values(scene, crops[k]);
      imaging.backward(scene, crops[k], grad, gx_two[k]);
    });
  for (std::thread& w : workers) w.join();
  for (int k = 0; k < 2; ++k) {
    CHECK(two[k] == one[k]);
    CHECK(gx_two[k] == gx_one[k]);
  }
  const ImagingTimings t = imaging.timings();
  CHECK(t.render_s > 0.0);
  CHECK(t.adjoint_s > 0.0);
}

TEST_CASE("render: one Renderer rendering from two threads at once gives the one-thread images") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  TraceOptions trace;
  trace.rings = 4;
  trace.fields = 5;
  RenderOptions ro;
  ro.threads = 1;
  FloatImage a(120, 90, 3), b(96, 64, 1);
  for (std::size_t i = 0; i < a.pixels.size(); ++i)
    a.pixels[i] = static_cast<float>((i * 7919) % 101) / 100.0f;
  for (std::size_t i = 0; i < b.pixels.size(); ++i)
    b.pixels[i] = static_cast<float>((i * 104729) % 97) / 96.0f;
  const Renderer reference(build_imaging_model(lens, trace), ro);
  const FloatImage ra = reference.render(a).image, rb = reference.render(b).image;
  const Renderer shared(build_imaging_model(lens, trace), ro);  // empty caches
  FloatImage sa, sb;
  std::thread ta([&] { sa = shared.render(a).image; });
  std::thread tb([&] { sb = shared.render(b).image; });
  ta.join();
  tb.join();
  CHECK(sa.pixels == ra.pixels);
  CHECK(sb.pixels == rb.pixels);
}

}  // namespace test_joint_robust
