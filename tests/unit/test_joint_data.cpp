// The joint optimization's pieces that need neither libtorch nor the imaging: the training data
// (deterministic crops, the held-out split, targets files), the gradient of l_lens against
// finite differences, and the paraxial-image-solve ablation flag.
#include <doctest/doctest.h>
#include <fmt/format.h>

#include <cmath>
#include <filesystem>

#include "lensopt/core/atomic_file.h"
#include "lensopt/core/error.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/joint/data.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/optimize/design_gradient.h"
#include "test_joint_support.h"
#include "test_support.h"

namespace test_joint_data {

using namespace lensopt;

namespace {

DataOptions small_data() {
  DataOptions d;
  d.builtin_scenes = 3;
  d.builtin_width = 96;
  d.builtin_height = 64;
  d.crop_px = 32;
  d.batch_size = 3;
  d.eval_crops = 4;
  d.seed = 7;
  return d;
}

}  // namespace

TEST_CASE(
    "joint data: crops are deterministic from the seed, inside the scene, from training scenes") {
  JointData a(small_data()), b(small_data());
  REQUIRE(a.scenes().size() == 3);
  CHECK(a.eval_scenes() == std::vector<int>{2});
  CHECK(a.train_scenes() == std::vector<int>{0, 1});
  // The scenes are the same images for the same seed; dead leaves differ from each other.
  CHECK(a.scenes()[1].image.pixels == b.scenes()[1].image.pixels);
  CHECK(a.scenes()[1].image.pixels != a.scenes()[2].image.pixels);
  bool moved = false;
  for (int i = 0; i < 20; ++i) {
    const auto ba = a.next_batch(), bb = b.next_batch();
    REQUIRE(ba.size() == 3);
    for (std::size_t k = 0; k < ba.size(); ++k) {
      CHECK(ba[k].scene == bb[k].scene);
      CHECK(ba[k].crop.x0 == bb[k].crop.x0);
      CHECK(ba[k].crop.y0 == bb[k].crop.y0);
      CHECK(ba[k].scene != 2);
      CHECK(ba[k].crop.x0 >= 0);
      CHECK(ba[k].crop.x0 + 32 <= 96);
      CHECK(ba[k].crop.y0 + 32 <= 64);
      moved = moved || ba[k].crop.x0 != ba[0].crop.x0;
    }
  }
  CHECK(moved);
  // The generator state round-trips: the same next batch.
  const std::string state = a.rng_state();
  const auto next = a.next_batch();
  a.set_rng_state(state);
  const auto again = a.next_batch();
  for (std::size_t k = 0; k < next.size(); ++k) CHECK(next[k].crop.x0 == again[k].crop.x0);
  // restart() replays the stream from the seed.
  JointData c(small_data());
  const auto first = c.next_batch();
  c.next_batch();
  c.restart();
  CHECK(c.next_batch()[0].crop.y0 == first[0].crop.y0);
  // Evaluation crops: the held-out scene's 3 x 2 tiles, 4 of them, fixed.
  REQUIRE(a.eval_samples().size() == 4);
  for (const Sample& s : a.eval_samples()) {
    CHECK(s.scene == 2);
    CHECK(s.crop.width == 32);
  }
  const FloatImage crop = a.crop(a.eval_samples()[1]);
  CHECK(crop.width == 32);
  CHECK(crop.at(3, 4, 1) == a.scenes()[2].image.at(a.eval_samples()[1].crop.x0 + 3,
                                                   a.eval_samples()[1].crop.y0 + 4, 1));
}

TEST_CASE("joint data: a directory of images, its split and its targets files") {
  const auto dir = test::joint_temp_dir("lensopt_test_joint_data");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  for (int i = 0; i < 5; ++i)
    write_image(dir / fmt::format("img{}.png", i), make_dead_leaves(48, 40, i));
  write_file_atomic(dir / "broken.png", "not a png");
  write_file_atomic(dir / "img1.targets.txt", "# class, box\n3, 0.5 0.25\n1e-1\n");
  DataOptions d;
  d.images_dir = dir;
  d.crop_px = 40;
  d.holdout_fraction = 0.4;
  JointData data(d);
  CHECK(data.scenes().size() == 5);  // broken.png reported and skipped
  bool noted = false;
  for (const auto& n : data.notes()) noted = noted || n.find("broken.png") != std::string::npos;
  CHECK(noted);
  CHECK(data.eval_scenes().size() == 2);
  CHECK(data.train_scenes().size() == 3);
  CHECK(data.scenes()[1].targets.filename() == "img1.targets.txt");
  CHECK(data.scenes()[0].targets.empty());
  CHECK(read_targets_file(data.scenes()[1].targets) == std::vector<double>{3, 0.5, 0.25, 0.1});
  write_file_atomic(dir / "bad.targets.txt", "1 2\n3 x4\n");
  try {
    read_targets_file(dir / "bad.targets.txt");
    FAIL("a bad number was accepted");
  } catch (const Error& e) {
    CHECK(e.where().line == 2);
    CHECK(e.where().column == 3);
  }
  // Too few images.
  d.crop_px = 48;  // larger than every image: all skipped
  CHECK_THROWS_AS(JointData{d}, Error);
  std::filesystem::remove_all(dir);
}

TEST_CASE("joint: the gradient of l_lens matches central finite differences") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  const LensParameterization param(lens, GlassSpace(*load_catalog("ohara")));
  TraceOptions sampling;
  sampling.rings = 4;
  sampling.fields = 3;
  DesignLossOptions loss;
  loss.min_image_clearance_mm = 13.0;  // make the ray-path hinge active
  std::vector<double> x = param.from_lens(lens);
  const DesignValueGradient g =
      design_loss_gradient(param, x, GlassMode::kContinuous, {}, sampling, loss);
  REQUIRE(g.finite);
  CHECK(g.loss.ray_path_mm > 0);
  for (int i = 0; i < param.size(); ++i) {
    const double h = 1e-6;
    std::vector<double> xp = x, xm = x;
    xp[i] += h;
    xm[i] -= h;
    const double fp =
        design_loss_gradient(param, xp, GlassMode::kContinuous, {}, sampling, loss).loss.total;
    const double fm =
        design_loss_gradient(param, xm, GlassMode::kContinuous, {}, sampling, loss).loss.total;
    const double fd = (fp - fm) / (2 * h);
    INFO(param.variables()[i].name, ": jet ", g.gradient[i], " fd ", fd);
    CHECK(std::abs(g.gradient[i] - fd) <= 1e-5 * std::max(1.0, std::abs(fd)));
  }
}

TEST_CASE("joint: without the paraxial image solve the last spacing is a plain variable") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  LensParameterization solve(lens, GlassSpace(*load_catalog("ohara")));
  LensParameterization plain(lens, GlassSpace(*load_catalog("ohara")));
  plain.set_paraxial_image_solve(false);
  CHECK(solve.paraxial_image_solve());
  const std::vector<double> xs = solve.from_lens(lens), xp = plain.from_lens(lens);
  const int last = static_cast<int>(lens.surfaces.size()) - 1;
  int d = -1;
  for (int i = 0; i < solve.size(); ++i)
    if (solve.variables()[i].kind == LensVariable::Kind::kDefocus) d = i;
  REQUIRE(d >= 0);
  const Lens ls = solve.to_lens(xs.data(), GlassMode::kQuantized);
  const Lens lp = plain.to_lens(xp.data(), GlassMode::kQuantized);
  // Same lens either way at the start; the plain variable is t / f.
  CHECK(lp.surfaces[last].thickness_mm ==
        doctest::Approx(ls.surfaces[last].thickness_mm).epsilon(1e-12));
  CHECK(xp[d] * plain.focal_length_mm() == doctest::Approx(ls.surfaces[last].thickness_mm));
  // Moving a curvature refocuses with the solve and not without it.
  std::vector<double> xs2 = xs, xp2 = xp;
  xs2[0] += 0.05;
  xp2[0] += 0.05;
  const double ts = solve.to_lens(xs2.data(), GlassMode::kQuantized).surfaces[last].thickness_mm;
  const double tp = plain.to_lens(xp2.data(), GlassMode::kQuantized).surfaces[last].thickness_mm;
  CHECK(tp == doctest::Approx(ls.surfaces[last].thickness_mm).epsilon(1e-12));
  CHECK(std::abs(ts - tp) > 1e-3);
}

}  // namespace test_joint_data
