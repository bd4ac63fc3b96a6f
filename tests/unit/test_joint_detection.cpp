// The joint optimization with object detection (issue 19): a tiny generated COCO dataset runs
// the paper's four settings; the perfect-optics detector is trained once and reused (a second run
// that loads it reproduces every setting exactly); a run resumed from a checkpoint follows the
// uninterrupted trajectory; the detection loss's gradient through the whole chain (boxes held)
// matches central finite differences. Small scenes, crops and sampling keep it to seconds.
#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/detection/crop_boxes.h"
#include "lensopt/detection/scenes.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/joint/joint.h"
#include "lensopt/lens/lens_io.h"
#include "test_joint_support.h"
#include "test_support.h"

namespace test_joint_detection {

using namespace lensopt;

namespace {

Lens doublet() {
  return read_lens(test::source_dir() / "lenses" / "doublet.toml");
}

std::filesystem::path fresh_dir(const std::string& name) {
  const auto dir = test::joint_temp_dir(name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

using test::tiny_detection_options;

}  // namespace

TEST_CASE("joint detection: the four settings, and the perfect-optics detector reused") {
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_detection");
  JointOptions o = tiny_detection_options(dir);
  o.perfect_task_out = dir / "perfect.pt";
  const JointResult r = optimize_joint(doublet(), o);
  CHECK(!r.interrupted);
  CHECK(r.metric_name == "AP");
  CHECK(r.eval_crops == 3);
  REQUIRE(r.settings.size() == 4);
  const char* names[] = {"perfect", "fixed/fixed", "fixed/trained", "joint"};
  for (int i = 0; i < 4; ++i) {
    const JointSettingResult& s = r.settings[i];
    INFO(s.name);
    CHECK(s.name == names[i]);
    CHECK(s.done);
    CHECK(s.metric >= -1.0);
    CHECK(s.metric <= 1.0);
    if (s.metric >= 0) CHECK(s.ap50 >= s.metric);
    if (i == 0) {
      CHECK(std::isnan(s.mean_spot_um));
      CHECK(std::isnan(s.psnr_db));
      CHECK(std::isnan(s.ssim));
    } else {
      CHECK(s.mean_spot_um > 0);
      CHECK(s.psnr_db > 10);
      CHECK(s.ssim > 0);
      CHECK(s.ssim <= 1);
    }
  }
  // Perfect optics (4 base steps + 4 more, the budget of the others), fixed/trained (4) and
  // joint (4) train; fixed/fixed does not.
  CHECK(r.steps_done == 16);
  const auto rows = test::csv_rows(dir / "log.csv");
  REQUIRE(rows.size() == 17);
  CHECK(rows[1][0] == "perfect");
  CHECK(rows[8][0] == "perfect");
  CHECK(rows[9][0] == "fixed/trained");
  CHECK(rows[13][0] == "joint");
  for (int i = 13; i < 17; ++i)
    CHECK(std::stod(rows[i][13]) > 0);  // the detector's loss reaches the lens
  CHECK(std::stod(rows[9][13]) == 0);
  // The perfect row's last 4 steps have the fine-tunes' schedule (the task learning rate, column
  // 3) and the base's 4 steps the same (the base has as many steps here).
  for (int i = 0; i < 4; ++i) {
    CHECK(rows[5 + i][3] == rows[9 + i][3]);
    CHECK(rows[5 + i][3] == rows[13 + i][3]);
    CHECK(rows[1 + i][3] == rows[9 + i][3]);
  }
  // Both fine-tunes start from the same (base) detector on the same crops and lens.
  CHECK(rows[9][5] == rows[13][5]);
  const LensParameterization param(doublet(), GlassSpace(*load_catalog("ohara")));
  CHECK(r.x != param.from_lens(doublet()));
  REQUIRE(std::filesystem::exists(dir / "perfect.pt"));

  // The same run from the saved base detector: its 4 base steps are not trained again (only the
  // perfect row's continuation), and every setting scores exactly as before.
  JointOptions again = o;
  again.perfect_task_out.clear();
  again.pretrained_task = dir / "perfect.pt";
  again.log_csv = dir / "again.csv";
  const JointResult r2 = optimize_joint(doublet(), again);
  REQUIRE(r2.settings.size() == 4);
  CHECK(r2.steps_done == 12);
  for (int i = 0; i < 4; ++i) {
    INFO(r.settings[i].name);
    CHECK(r2.settings[i].metric == r.settings[i].metric);
    CHECK(r2.settings[i].ap50 == r.settings[i].ap50);
  }
  CHECK(r2.x == r.x);
  // Step for step the same losses: the loaded detector is the trained one, bit for bit.
  const auto rows2 = test::csv_rows(dir / "again.csv");
  REQUIRE(rows2.size() == 13);
  for (int i = 1; i < 13; ++i) CHECK(rows2[i] == rows[i + 4]);
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint detection: a resumed run follows the uninterrupted trajectory") {
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_detection_resume");
  JointOptions o = tiny_detection_options(dir);
  o.run_baselines = false;  // perfect, then joint
  o.log_csv = dir / "straight.csv";
  const JointResult straight = optimize_joint(doublet(), o);
  REQUIRE(straight.settings.size() == 2);
  // Stopped in the perfect-optics phase, resumed, stopped in the joint phase, resumed.
  o.log_csv = dir / "resumed.csv";
  o.checkpoint_every = 1;
  o.checkpoint_dir = dir / "ckpt";
  o.stop_after_steps = 3;
  CHECK(optimize_joint(doublet(), o).interrupted);
  o.resume_dir = dir / "ckpt";
  CHECK(optimize_joint(doublet(), o).interrupted);
  o.stop_after_steps = -1;
  const JointResult resumed = optimize_joint(doublet(), o);
  CHECK(!resumed.interrupted);
  CHECK(read_file(dir / "resumed.csv") == read_file(dir / "straight.csv"));
  CHECK(resumed.x == straight.x);
  for (int i = 0; i < 2; ++i) {
    CHECK(resumed.settings[i].metric == straight.settings[i].metric);
    CHECK(resumed.settings[i].ap75 == straight.settings[i].ap75);
  }
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint detection: a task and a dataset that do not fit are refused") {
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_detection_refused");
  JointOptions o = tiny_detection_options(dir);
  o.data.crop_px = 40;  // the built-in detector needs multiples of 16
  CHECK_THROWS_WITH_AS(optimize_joint(doublet(), o), doctest::Contains("multiple of 16"), Error);
  o.data.crop_px = 64;
  o.task = "restoration";
  CHECK_THROWS_WITH_AS(optimize_joint(doublet(), o), doctest::Contains("not a detector"), Error);
  o.task = "detection";
  o.data.annotations.clear();
  CHECK_THROWS_WITH_AS(optimize_joint(doublet(), o), doctest::Contains("detection dataset"), Error);
  std::filesystem::remove_all(dir);
}

TEST_CASE(
    "joint detection: the detection loss's gradient through the chain matches finite differences") {
  // Lens variables -> PSFs, RI, distortion (Jets) -> rendered crops (double) -> the built-in
  // detector's loss (float64) with the crops' boxes held fixed -> backward through the detector
  // and the imaging adjoint.
  if (!torch_available()) return;
  const auto dir = fresh_dir("lensopt_test_joint_detection_gradient");
  const Lens lens = doublet();
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  DifferentiableImagingOptions io;
  io.sampling.rings = 4;
  io.sampling.fields = 5;
  io.res_factor = 2;
  DifferentiableImaging imaging(param, GlassMode::kContinuous, {}, io);
  DataOptions d;
  d.annotations = test::tiny_detection_dataset(dir);
  d.crop_px = 48;
  JointData data(d);
  std::vector<Sample> samples;
  std::vector<std::vector<GroundTruth>> boxes;
  for (int s = 0; s < 2; ++s) {
    const Sample sample{s, CropWindow{40 * s, 30, 48, 48}};
    samples.push_back(sample);
    boxes.push_back(
        crop_ground_truth(data.scenes()[s].boxes, nullptr,
                          CropFrame{double(sample.crop.x0), double(sample.crop.y0), 48, 48}));
  }
  TaskOptions t;
  t.double_precision = true;
  t.learning_rate = 1e-2;
  auto task = make_task("detection", t);
  auto batch_at = [&](const std::vector<double>& x) {
    imaging.prepare(x);
    TaskBatch batch;
    for (const Sample& s : samples) {
      const FloatImage& scene = data.scenes()[s.scene].image;
      batch.rendered.push_back(imaging.render(scene, s.crop));
      batch.rendered_values.push_back(imaging.render_values(scene, s.crop));
      batch.sharp.push_back(data.crop(s));
    }
    batch.boxes = boxes;
    return batch;
  };
  const std::vector<double> x = param.from_lens(lens);
  const TaskBatch batch = batch_at(x);
  for (int i = 0; i < 3; ++i) task->step(batch, true, false);
  std::vector<double> grad;
  const double loss = task_loss_gradient(imaging, *task, data, samples, x, &grad, boxes);
  CHECK(loss == doctest::Approx(task->step(batch, false, false).loss).epsilon(1e-6));
  REQUIRE(grad.size() == x.size());
  double worst = 0;
  int checked = 0;
  for (int i = 0; i < param.size(); i += 2) {
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
    ++checked;
  }
  CHECK(checked >= 3);
  MESSAGE("detection chain: worst relative error ", worst, " over ", checked, " variables");
  std::filesystem::remove_all(dir);
}

}  // namespace test_joint_detection
