// The boxes of a crop through the image formation (detection/crop_boxes.h): without distortion
// they are the scene boxes moved and clipped; with the Doublet's distortion at 2x, a detector
// that predicts exactly its training targets scores AP50 = 1 after the correction, and the
// corrected boxes lie within 0.5 px of the evaluation ground truth.
#include <doctest/doctest.h>

#include <cmath>

#include "lensopt/detection/crop_boxes.h"
#include "lensopt/formats/lens_file.h"
#include "lensopt/lens/lens_io.h"
#include "lensopt/render/render.h"
#include "test_support.h"

namespace test_detection_crops {

using namespace lensopt;

namespace {

// Boxes of several sizes over a 320 x 180 scene, some across the crop's borders.
std::vector<GroundTruth> scene_boxes() {
  std::vector<GroundTruth> out;
  int k = 0;
  for (int gy = 0; gy < 4; ++gy)
    for (int gx = 0; gx < 6; ++gx) {
      GroundTruth g;
      g.image = 0;
      g.category = 1 + (k % 6);
      const double w = 12 + 7 * ((k * 5) % 6), h = 10 + 6 * ((k * 7) % 5);
      g.box = {8.0 + gx * 52, 6.0 + gy * 43, 8.0 + gx * 52 + w, 6.0 + gy * 43 + h};
      g.area = 123;  // a segment area: a crop makes it the box's
      out.push_back(g);
      ++k;
    }
  return out;
}

double largest_difference(const Box& a, const Box& b) {
  return std::max(
      {std::abs(a.x0 - b.x0), std::abs(a.y0 - b.y0), std::abs(a.x1 - b.x1), std::abs(a.y1 - b.y1)});
}

}  // namespace

TEST_CASE("crop boxes: without distortion, the scene boxes moved and clipped") {
  const std::vector<GroundTruth> boxes = scene_boxes();
  const CropFrame crop{60, 30, 128, 96};
  const std::vector<GroundTruth> target = crop_ground_truth(boxes, nullptr, crop);
  const std::vector<GroundTruth> eval = crop_evaluation_ground_truth(boxes, nullptr, crop);
  std::size_t kept = 0;
  bool clipped = false;
  for (const GroundTruth& g : boxes) {
    const auto b = crop_box(g.box, crop.x0, crop.y0, crop.width, crop.height);
    if (!b) continue;
    REQUIRE(kept < target.size());
    CHECK(target[kept].box.x0 == b->x0);
    CHECK(target[kept].box.y1 == b->y1);
    CHECK(target[kept].category == g.category);
    CHECK(target[kept].area == -1);
    CHECK(eval[kept].box.x1 == b->x1);
    clipped = clipped || b->width() < g.box.width() || b->height() < g.box.height();
    ++kept;
  }
  CHECK(kept == target.size());
  CHECK(kept == eval.size());
  CHECK(kept >= 4);
  CHECK(clipped);
  std::vector<Detection> same;
  for (const GroundTruth& g : target) same.push_back({0, g.category, g.box, 0.9});
  correct_crop_detections(same, nullptr, crop);
  CHECK(same[0].box.x0 == target[0].box.x0);
}

TEST_CASE(
    "crop boxes: the corrected training targets score AP50 = 1 against the evaluation truth") {
  const Lens lens = read_lens(test::source_dir() / "lenses" / "doublet.toml");
  TraceOptions trace;
  trace.rings = 8;
  const ImagingModel model = build_imaging_model(lens, trace);
  const BoxDistortion distortion(model, 320, 180, 2);  // 2x: the axis at the bottom-right corner
  const std::vector<GroundTruth> boxes = scene_boxes();
  for (const CropFrame crop :
       {CropFrame{0, 0, 128, 96}, CropFrame{60, 30, 128, 96}, CropFrame{190, 82, 128, 96}}) {
    const std::vector<GroundTruth> target = crop_ground_truth(boxes, &distortion, crop);
    const std::vector<GroundTruth> eval = crop_evaluation_ground_truth(boxes, &distortion, crop);
    REQUIRE(target.size() == eval.size());
    REQUIRE(!target.empty());
    // A detector that finds exactly what it was trained on, corrected.
    std::vector<Detection> found;
    for (const GroundTruth& g : target) found.push_back({0, g.category, g.box, 0.9});
    correct_crop_detections(found, &distortion, crop);
    // How far the correction moves the boxes (the test is not vacuous near the far corner), and
    // how far the corrected ones are from the evaluation truth.
    double moved = 0, worst = 0;
    for (std::size_t i = 0; i < found.size(); ++i) {
      moved = std::max(moved, largest_difference(found[i].box, target[i].box));
      worst = std::max(worst, largest_difference(found[i].box, eval[i].box));
    }
    MESSAGE("crop at " << crop.x0 << "," << crop.y0 << ": " << target.size()
                       << " boxes, distortion moves them up to " << moved
                       << " px, corrected predictions within " << worst << " px of the truth");
    if (crop.x0 == 0) CHECK(moved > 2.0);
    CHECK(worst < 0.5);
    const CocoStats stats = evaluate_coco(eval, found);
    CHECK(stats.ap50 == doctest::Approx(1.0));
    // Uncorrected, the same predictions miss some boxes near the far corner.
    if (crop.x0 == 0) {
      std::vector<Detection> raw;
      for (const GroundTruth& g : target) raw.push_back({0, g.category, g.box, 0.9});
      CHECK(evaluate_coco(eval, raw).ap < stats.ap);
    }
  }
}

}  // namespace test_detection_crops
