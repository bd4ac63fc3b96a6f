// The joint optimization's libtorch tasks: the restoration network (identity when untrained, its
// image gradient against finite differences, exact save/load of weights and Adam state) and a
// TorchScript task defined here from TorchScript source. One of the two test files with libtorch
// headers (test_torch.h).
// libtorch first (test_torch.h): glog's CHECK gives way to doctest's.
// clang-format off
#include "test_torch.h"
// clang-format on

#include <doctest/doctest.h>

#include <cmath>
#include <filesystem>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/joint/data.h"
#include "lensopt/joint/task.h"
#include "lensopt/render/metrics.h"
#include "test_joint_support.h"

// Declared in test_joint_support.h: outside this file's namespace.
namespace lensopt::test {

std::filesystem::path write_test_torchscript_module(const std::filesystem::path& dir) {
#ifdef LENSOPT_WITH_TORCH
  // A one-layer residual restorer with its loss: forward(images, targets) -> MSE.
  torch::manual_seed(5);
  torch::jit::Module module("Restorer");
  module.register_parameter("weight", torch::randn({3, 3, 3, 3}) * 0.01, false);
  module.register_parameter("bias", torch::zeros({3}), false);
  module.define(R"JIT(
def forward(self, images, targets):
    restored = images + torch.conv2d(images, self.weight, self.bias, [1, 1], [1, 1])
    return torch.mean((restored - targets) ** 2)
)JIT");
  std::filesystem::create_directories(dir);
  const std::filesystem::path path = dir / "restorer.pt";
  module.save(path.string());
  return path;
#else
  (void)dir;
  return {};
#endif
}

}  // namespace lensopt::test

namespace test_joint_task {

using namespace lensopt;

namespace {

// A batch of two crops: dead leaves, and the same blurred by a 3-tap box in x.
TaskBatch test_batch() {
  const FloatImage scene = make_dead_leaves(40, 36, 3);
  TaskBatch batch;
  for (int k = 0; k < 2; ++k) {
    const FloatImage sharp = crop_image(scene, CropWindow{k * 8, k * 4, 24, 20});
    FloatImage blurred = sharp;
    for (int y = 0; y < sharp.height; ++y)
      for (int x = 1; x + 1 < sharp.width; ++x)
        for (int c = 0; c < 3; ++c)
          blurred.at(x, y, c) =
              (sharp.at(x - 1, y, c) + sharp.at(x, y, c) + sharp.at(x + 1, y, c)) / 3.0f;
    batch.rendered.push_back(blurred);
    batch.sharp.push_back(sharp);
    batch.targets.emplace_back();
  }
  return batch;
}

}  // namespace

TEST_CASE("joint task: without libtorch the task says so") {
  if (torch_available()) return;
  try {
    make_task("restoration", TaskOptions{});
    FAIL("make_task worked without libtorch");
  } catch (const Error& e) {
    CHECK(std::string(e.what()).find("LENSOPT_WITH_TORCH=OFF") != std::string::npos);
  }
}

#ifdef LENSOPT_WITH_TORCH

TEST_CASE("joint task: the untrained restoration network is the identity") {
  TaskOptions o;
  auto task = make_task("restoration", o);
  const TaskBatch batch = test_batch();
  double psnr = 0;
  for (std::size_t i = 0; i < batch.rendered.size(); ++i)
    psnr += psnr_db(batch.rendered[i], batch.sharp[i], 3) / batch.rendered.size();
  CHECK(task->metric(batch) == doctest::Approx(psnr).epsilon(1e-5));
  const auto restored = task->predict(batch);
  REQUIRE(restored.size() == 2);
  CHECK(restored[1].pixels == batch.rendered[1].pixels);
  CHECK(task->metric_name() == "PSNR (dB)");
  CHECK_THROWS_AS(make_task("segmentation", o), Error);
  CHECK_THROWS_AS(make_task("torchscript:/nonexistent/model.pt", o), Error);
}

TEST_CASE("joint task: restoration trains, and its image gradient matches finite differences") {
  TaskOptions o;
  o.double_precision = true;
  o.learning_rate = 3e-3;
  o.features = 8;
  o.layers = 3;
  auto task = make_task("restoration", o);
  TaskBatch batch = test_batch();
  const double before = task->step(batch, false, false).loss;
  for (int i = 0; i < 30; ++i) task->step(batch, true, false);
  const double after = task->step(batch, false, false).loss;
  CHECK(after < 0.8 * before);
  const TaskOutput out = task->step(batch, false, true);
  CHECK(out.loss == doctest::Approx(after).epsilon(1e-12));
  REQUIRE(out.grad_rendered.size() == 2);
  // The images are float: step by a float-exact 2^-12 and compare with the float gradient.
  const float h = 1.0f / 4096;
  for (const auto& [b, x, y, c] : {std::array<int, 4>{0, 5, 7, 0}, std::array<int, 4>{1, 12, 3, 2},
                                   std::array<int, 4>{1, 0, 0, 1}}) {
    TaskBatch plus = batch, minus = batch;
    plus.rendered[b].at(x, y, c) += h;
    minus.rendered[b].at(x, y, c) -= h;
    const double fd = (task->step(plus, false, false).loss - task->step(minus, false, false).loss) /
                      (2.0 * (plus.rendered[b].at(x, y, c) - batch.rendered[b].at(x, y, c)));
    const double g = out.grad_rendered[b].at(x, y, c);
    INFO("pixel ", b, " ", x, " ", y, " ", c, ": autograd ", g, " fd ", fd);
    CHECK(std::abs(g - fd) <= 1e-3 * std::abs(fd) + 1e-9);
  }
}

TEST_CASE("joint task: save and load restore the weights and the Adam state exactly") {
  const auto dir = test::joint_temp_dir("lensopt_test_joint_task");
  std::filesystem::create_directories(dir);
  TaskOptions o;
  o.features = 8;
  o.layers = 3;
  auto task = make_task("restoration", o);
  const TaskBatch batch = test_batch();
  for (int i = 0; i < 3; ++i) task->step(batch, true, false);
  task->save(dir / "state.pt");
  const double l1 = task->step(batch, true, false).loss;
  const double l2 = task->step(batch, true, false).loss;
  auto other = make_task("restoration", o);
  other->load(dir / "state.pt");
  CHECK(other->step(batch, true, false).loss == l1);
  CHECK(other->step(batch, true, false).loss == l2);
  task->save_network(dir / "net.pt");
  CHECK(std::filesystem::file_size(dir / "net.pt") > 0);
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint task: a TorchScript module trains through torchscript:MODEL.pt") {
  const auto dir = test::joint_temp_dir("lensopt_test_joint_ts");
  const std::filesystem::path model = test::write_test_torchscript_module(dir);
  TaskOptions o;
  o.learning_rate = 2e-3;
  auto task = make_task("torchscript:" + model.string(), o);
  // Learn the blur itself (a 3x3 convolution can represent it exactly).
  TaskBatch batch = test_batch();
  std::swap(batch.rendered, batch.sharp);
  const double before = task->step(batch, false, false).loss;
  for (int i = 0; i < 60; ++i) task->step(batch, true, false);
  const double after = task->step(batch, false, true).loss;
  CHECK(after < 0.5 * before);
  CHECK(task->metric(batch) == doctest::Approx(-after));
  const TaskOutput out = task->step(batch, false, true);
  REQUIRE(out.grad_rendered.size() == 2);
  CHECK(out.grad_rendered[0].width == 24);
  // Targets files: a module whose loss reads them (mean squared distance of the image means to
  // the targets' first number).
  torch::jit::Module m("Means");
  m.register_parameter("gain", torch::ones({1}), false);
  m.define(R"JIT(
def forward(self, images, targets):
    means = torch.mean(images, [1, 2, 3]) * self.gain
    return torch.mean((means - targets[:, 0]) ** 2)
)JIT");
  m.save((dir / "means.pt").string());
  auto means = make_task("torchscript:" + (dir / "means.pt").string(), o);
  TaskBatch with = batch;
  with.targets = {dir / "a.targets.txt", dir / "b.targets.txt"};
  write_file_atomic(dir / "a.targets.txt", "0.25 7\n");
  write_file_atomic(dir / "b.targets.txt", "0.75, 8\n");
  double expected = 0;
  for (int i = 0; i < 2; ++i) {
    double mean = 0;
    for (float v : batch.rendered[i].pixels) mean += v;
    mean /= batch.rendered[i].pixels.size();
    expected += std::pow(mean - (i == 0 ? 0.25 : 0.75), 2) / 2;
  }
  CHECK(means->step(with, false, false).loss == doctest::Approx(expected).epsilon(1e-5));
  with.targets[1].clear();  // some but not all
  CHECK_THROWS_AS(means->step(with, false, false), Error);
  std::filesystem::remove_all(dir);
}

#endif

}  // namespace test_joint_task
