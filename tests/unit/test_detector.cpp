// The detection tasks: the built-in detector learns the generated scenes (its AP rises from the
// untrained one's), and a TorchScript detector defined here by the contract of joint/detector.h
// trains and returns its detections.
// libtorch first (test_torch.h): glog's CHECK gives way to doctest's.
// clang-format off
#include "test_torch.h"
// clang-format on

#include <doctest/doctest.h>
#include <unistd.h>

#include <filesystem>

#include "lensopt/core/error.h"
#include "lensopt/detection/scenes.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/joint/detector.h"
#include "lensopt/joint/joint.h"
#include "lensopt/joint/task.h"
#include "lensopt/lens/lens_io.h"
#include "test_joint_support.h"
#include "test_support.h"

namespace test_detector {

using namespace lensopt;

#ifdef LENSOPT_WITH_TORCH

namespace {

// Batches of 128 x 128 crops (top-left, centre-bottom) of generated scenes with their boxes.
TaskBatch scene_batch(int first_seed, int scenes) {
  TaskBatch batch;
  for (int s = 0; s < scenes; ++s) {
    const DetectionScene scene = make_detection_scene(256, 144, first_seed + s);
    const int x0 = (s % 2) * 128, y0 = 16;
    FloatImage crop(128, 128, 3);
    for (int y = 0; y < 128; ++y)
      for (int x = 0; x < 128; ++x)
        for (int c = 0; c < 3; ++c) crop.at(x, y, c) = scene.image.at(x0 + x, y0 + y, c);
    std::vector<GroundTruth> boxes;
    for (const GroundTruth& g : scene.boxes)
      if (auto b = crop_box(g.box, x0, y0, 128, 128)) {
        GroundTruth moved = g;
        moved.box = *b;
        boxes.push_back(moved);
      }
    batch.rendered.push_back(crop);
    batch.sharp.push_back(crop);
    batch.boxes.push_back(boxes);
  }
  return batch;
}

}  // namespace

TEST_CASE("detector: the built-in detector learns the generated scenes") {
  TaskOptions o;
  o.learning_rate = 2e-3;
  o.seed = 3;
  auto task = make_task("detection", o);
  CHECK(task->metric_name() == "AP");
  const TaskBatch batch = scene_batch(100, 4);
  const double loss0 = task->step(batch, false, false).loss;
  const double ap0 = task->metric(batch);
  for (int k = 0; k < 150; ++k) task->step(batch, true, false);
  const double loss1 = task->step(batch, false, false).loss;
  const double ap1 = task->metric(batch);
  MESSAGE("built-in detector on 4 crops, 150 steps: loss " << loss0 << " -> " << loss1 << ", AP "
                                                           << ap0 << " -> " << ap1);
  CHECK(loss1 < 0.5 * loss0);
  CHECK(ap1 > ap0 + 0.1);
  CHECK(ap1 > 0.5);  // most of the 4 crops' objects found (0.90 with the version-2 detector)
  // The image gradient has the batch's layout and is not zero.
  const TaskOutput out = task->step(batch, false, true);
  REQUIRE(out.grad_rendered.size() == 4);
  double norm = 0;
  for (float v : out.grad_rendered[0].pixels) norm += double(v) * v;
  CHECK(norm > 0);
  // Detections: at most 100 per image, inside a sane range, scores in (0, 1].
  const auto dets = task->detect(batch);
  REQUIRE(dets.size() == 4);
  for (const auto& list : dets) {
    CHECK(list.size() <= 100);
    for (const Detection& d : list) {
      CHECK(d.score > 0);
      CHECK(d.score <= 1);
      CHECK(d.category >= 1);
      CHECK(d.category <= 6);
    }
  }
  // Sides must be multiples of 16.
  TaskBatch odd = batch;
  odd.rendered.resize(1);
  odd.rendered[0] = FloatImage(120, 128, 3);
  odd.boxes.resize(1);
  CHECK_THROWS_AS(task->step(odd, false, false), lensopt::Error);
}

TEST_CASE("detector: state files round-trip, and the version-1 detector's are refused") {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt-test-detector-state-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  TaskOptions o;
  o.seed = 5;
  auto a = make_task("detection", o);
  const TaskBatch batch = scene_batch(200, 2);
  for (int k = 0; k < 3; ++k) a->step(batch, true, false);
  a->save(dir / "state.pt");
  // A second detector (another seed) loaded from the file continues the first one exactly.
  o.seed = 6;
  auto b = make_task("detection", o);
  CHECK(b->step(batch, false, false).loss != a->step(batch, false, false).loss);
  b->load(dir / "state.pt");
  for (int k = 0; k < 2; ++k)
    CHECK(b->step(batch, true, false).loss == a->step(batch, true, false).loss);
  // A file of the earlier detector has no "detector_version" entry (its network's entries only,
  // e.g. "s2.weight" and "optimizer"): refused, naming the file and what to do.
  {
    torch::serialize::OutputArchive old, optimizer;
    old.write("s2.weight", torch::zeros({16, 3, 3, 3}));
    old.write("optimizer", optimizer);
    old.save_to((dir / "old.pt").string());
  }
  CHECK_THROWS_WITH_AS(b->load(dir / "old.pt"), doctest::Contains("built-in detector's version 1"),
                       lensopt::Error);
  CHECK_THROWS_WITH_AS(b->load(dir / "old.pt"), doctest::Contains("train the detector again"),
                       lensopt::Error);
  std::filesystem::remove_all(dir);
}

TEST_CASE("detector: a TorchScript detector by the (images, boxes, labels) contract") {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("lensopt-test-detector-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  // One learned box for every image: the training loss is its squared distance to the valid
  // ground-truth boxes; evaluation returns it with score 0.9 and label 1, plus a padding row.
  torch::jit::Module m("FixedBox");
  m.register_parameter("box", torch::tensor({0.0f, 0.0f, 10.0f, 10.0f}), false);
  m.register_attribute("training", c10::BoolType::get(), true);  // nn.Module's flag
  m.define(R"JIT(
def forward(self, images, boxes, labels):
    if self.training:
        valid = (labels >= 0).to(images.dtype).unsqueeze(2)
        d = (boxes.to(images.dtype) - self.box.to(images.dtype)) ** 2 * valid
        return torch.sum(d) / torch.clamp(torch.sum(valid), min=1.0) + 0.0 * torch.mean(images)
    b = images.size(0)
    row = torch.cat([self.box.to(images.dtype), torch.tensor([0.9, 1.0], dtype=images.dtype)])
    pad = torch.zeros(6, dtype=images.dtype)
    return torch.stack([row, pad]).unsqueeze(0).repeat(b, 1, 1)
)JIT");
  m.save((dir / "fixed.pt").string());
  CHECK(is_torchscript_detector(dir / "fixed.pt"));
  TaskOptions o;
  o.learning_rate = 0.5;
  auto task = make_task("torchscript:" + (dir / "fixed.pt").string(), o);
  CHECK(task->metric_name() == "AP");
  TaskBatch batch;
  batch.rendered = {FloatImage(32, 32, 3, 0.5f), FloatImage(32, 32, 3, 0.5f)};
  batch.sharp = batch.rendered;
  GroundTruth g;
  g.category = 1;
  g.box = {4, 6, 20, 22};
  batch.boxes = {{g}, {g}};
  const double before = task->step(batch, false, false).loss;
  for (int k = 0; k < 200; ++k) task->step(batch, true, false);
  task->set_learning_rate(0.01);
  for (int k = 0; k < 200; ++k) task->step(batch, true, false);
  const double after = task->step(batch, false, false).loss;
  CHECK(after < 1e-2 * before);
  const auto dets = task->detect(batch);
  REQUIRE(dets.size() == 2);
  REQUIRE(dets[0].size() == 1);  // the padding row is dropped
  CHECK(dets[0][0].score == doctest::Approx(0.9));
  CHECK(dets[0][0].box.x0 == doctest::Approx(4).epsilon(1e-2));
  CHECK(task->metric(batch) == doctest::Approx(1.0));  // the learned box is the ground truth
  std::filesystem::remove_all(dir);
}

TEST_CASE("detector: a scripted detector by the contract trains jointly through torchscript:") {
  // The TorchScript path without torchvision (issue 19): a detector of the (images, boxes,
  // labels) contract whose training loss depends on the images (the learned box's distance to
  // the ground truth plus the images' mean squared contrast), so its gradient reaches the lens,
  // runs the four settings of `optimize --joint --task torchscript:MODEL.pt` on generated scenes.
  const auto dir = test::joint_temp_dir("lensopt_test_detector_joint");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  torch::jit::Module m("BoxAndContrast");
  m.register_parameter("box", torch::tensor({0.0f, 0.0f, 10.0f, 10.0f}), false);
  m.register_attribute("training", c10::BoolType::get(), true);
  m.define(R"JIT(
def forward(self, images, boxes, labels):
    if self.training:
        valid = (labels >= 0).to(images.dtype).unsqueeze(2)
        d = (boxes.to(images.dtype) - self.box.to(images.dtype)) ** 2 * valid
        contrast = torch.mean((images - torch.mean(images)) ** 2)
        return torch.sum(d) / torch.clamp(torch.sum(valid), min=1.0) * 1e-4 - contrast
    b = images.size(0)
    row = torch.cat([self.box.to(images.dtype), torch.tensor([0.9, 1.0], dtype=images.dtype)])
    return row.unsqueeze(0).unsqueeze(0).repeat(b, 1, 1)
)JIT");
  m.save((dir / "model.pt").string());
  REQUIRE(is_torchscript_detector(dir / "model.pt"));
  JointOptions o = test::tiny_detection_options(dir);
  o.task = "torchscript:" + (dir / "model.pt").string();
  o.task_options.learning_rate = 1e-2;
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  const JointResult r = optimize_joint(lens, o);
  CHECK(r.metric_name == "AP");
  REQUIRE(r.settings.size() == 4);
  for (const JointSettingResult& s : r.settings) {
    INFO(s.name);
    CHECK(s.done);
    CHECK(s.metric >= 0.0);
    CHECK(s.metric <= 1.0);
  }
  // The detector's loss reaches the lens in the joint rows, and the lens moves.
  const auto rows = test::csv_rows(dir / "log.csv");
  REQUIRE(rows.size() == 17);
  for (int i = 13; i < 17; ++i) {
    CHECK(rows[i][0] == "joint");
    CHECK(std::stod(rows[i][13]) > 0);
  }
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  CHECK(r.x != param.from_lens(lens));
  std::filesystem::remove_all(dir);
}

#endif

}  // namespace test_detector
