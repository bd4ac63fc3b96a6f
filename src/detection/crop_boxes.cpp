// The boxes of a crop through the image formation (rules in detection/crop_boxes.h).
#include "lensopt/detection/crop_boxes.h"

#include <fmt/format.h>

#include <map>
#include <optional>

#include "lensopt/core/error.h"

namespace lensopt {
namespace {

Box shifted(const Box& b, double dx, double dy) {
  return {b.x0 + dx, b.y0 + dy, b.x1 + dx, b.y1 + dy};
}

// The scene box as the full image shows it (distorted, or as it is).
Box imaged(const Box& box, const BoxDistortion* distortion) {
  return distortion ? distortion->distort_box(box) : box;
}

}  // namespace

std::vector<GroundTruth> crop_ground_truth(const std::vector<GroundTruth>& scene_boxes,
                                           const BoxDistortion* distortion, const CropFrame& crop,
                                           const CropRule& rule) {
  std::vector<GroundTruth> out;
  for (const GroundTruth& g : scene_boxes) {
    const auto b =
        crop_box(imaged(g.box, distortion), crop.x0, crop.y0, crop.width, crop.height, rule);
    if (!b) continue;
    GroundTruth moved = g;
    moved.box = *b;
    moved.area = -1;
    out.push_back(moved);
  }
  return out;
}

std::vector<GroundTruth> crop_evaluation_ground_truth(const std::vector<GroundTruth>& scene_boxes,
                                                      const BoxDistortion* distortion,
                                                      const CropFrame& crop, const CropRule& rule) {
  if (!distortion) return crop_ground_truth(scene_boxes, nullptr, crop, rule);
  std::vector<GroundTruth> out;
  for (const GroundTruth& g : scene_boxes) {
    const Box full = distortion->distort_box(g.box);
    const auto b = crop_box(full, crop.x0, crop.y0, crop.width, crop.height, rule);
    if (!b) continue;
    GroundTruth moved = g;
    moved.area = -1;
    const Box unclipped = shifted(full, -crop.x0, -crop.y0);
    if (b->x0 == unclipped.x0 && b->y0 == unclipped.y0 && b->x1 == unclipped.x1 &&
        b->y1 == unclipped.y1) {
      moved.box = shifted(g.box, -crop.x0, -crop.y0);
    } else {
      moved.box =
          shifted(distortion->undistort_box(shifted(*b, crop.x0, crop.y0)), -crop.x0, -crop.y0);
    }
    out.push_back(moved);
  }
  return out;
}

void correct_crop_detections(std::vector<Detection>& detections, const BoxDistortion* distortion,
                             const CropFrame& crop) {
  if (!distortion) return;
  for (Detection& d : detections)
    d.box =
        shifted(distortion->undistort_box(shifted(d.box, crop.x0, crop.y0)), -crop.x0, -crop.y0);
}

DetectionDataset rendered_annotations(const DetectionDataset& dataset, const ImagingModel& model,
                                      int res_factor, bool distortion) {
  DetectionDataset out;
  out.images = dataset.images;
  out.categories = dataset.categories;
  out.notes = dataset.notes;
  std::map<int, std::vector<GroundTruth>> by_image;
  for (const GroundTruth& g : dataset.annotations) by_image[g.image].push_back(g);
  for (const DetectionImage& image : dataset.images) {
    if (image.width <= 0 || image.height <= 0)
      throw Error(fmt::format("annotations of {}: the image's size is unknown", image.file_name));
    std::optional<BoxDistortion> d;
    if (distortion) d.emplace(model, image.width, image.height, res_factor);
    const CropFrame whole{0, 0, double(image.width), double(image.height)};
    CropRule rule;  // an annotated box stays, however small, while a quarter of it is inside
    rule.min_side_px = 0;
    for (const GroundTruth& g :
         crop_ground_truth(by_image[image.id], d ? &*d : nullptr, whole, rule))
      out.annotations.push_back(g);
  }
  return out;
}

}  // namespace lensopt
