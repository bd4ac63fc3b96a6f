// The boxes of one crop of a scene through the image formation (detection/boxes.h's
// transforms, composed): the detector's training targets, the evaluation's ground truth, and the
// correction of its predictions. Used by the joint optimization (joint/joint.h) and by
// `lensopt render --annotations`.
//
// Training target of a crop window (x0, y0, w, h) of a scene: each scene box (scene pixels) is
// distorted (the paper's edge-midpoint rule, when a distortion is given) in the full image's
// pixels, then moved and clipped by `crop_box`; a box the crop rule drops is left out.
// Evaluation: the predicted boxes are corrected (the inverse rule, in the full image's pixels)
// and compared with the ground truth in the undistorted frame: the objects the rendered crop
// shows (those the training target keeps), each as its scene box moved into the crop when the
// crop did not clip its distorted box, and otherwise as the inverse correction of the clipped
// distorted box (the part of the object the image shows). Without distortion both are the scene
// boxes moved and clipped. Crowd regions are kept with their flag; areas become the boxes'
// (area = -1), since a crop or a warp changes the segment area.
#pragma once

#include <vector>

#include "lensopt/detection/boxes.h"
#include "lensopt/detection/coco_eval.h"
#include "lensopt/detection/dataset.h"

namespace lensopt {

// A crop window of a scene image, pixels.
struct CropFrame {
  double x0 = 0, y0 = 0, width = 0, height = 0;
};
// The training target (see the header).
std::vector<GroundTruth> crop_ground_truth(const std::vector<GroundTruth>& scene_boxes,
                                           const BoxDistortion* distortion, const CropFrame& crop,
                                           const CropRule& rule = {});

// The ground truth of the same crop for evaluation, in the undistorted frame the corrected
// predictions are in: the objects the rendered crop shows (those `crop_ground_truth` keeps), each
// as its scene box moved into the crop when the crop did not clip it, and as the inverse
// correction of its clipped (distorted) box when it did (the visible part, undistorted). Without
// distortion this equals `crop_ground_truth`.
std::vector<GroundTruth> crop_evaluation_ground_truth(const std::vector<GroundTruth>& scene_boxes,
                                                      const BoxDistortion* distortion,
                                                      const CropFrame& crop,
                                                      const CropRule& rule = {});

// Predicted boxes of a crop (crop pixels) corrected for distortion (undistort_box in the full
// image's pixels, then back into the crop's), in place; nothing without `distortion`.
void correct_crop_detections(std::vector<Detection>& detections, const BoxDistortion* distortion,
                             const CropFrame& crop);

// The annotations of a rendered dataset (`lensopt render --annotations`): every image's boxes as
// the rendered full image shows them, i.e. `crop_ground_truth` over the whole image (distorted by
// the model's distortion at `res_factor` when `distortion`, clipped to the image; a box less than
// a quarter of which stays inside is dropped, small ones are kept). Pixel coordinates are not
// scaled by the resolution factor (the image is the sensor's quadrant, detection/boxes.h). Images,
// categories and file names are kept; every image must have its size (width, height > 0), else
// Error naming it.
DetectionDataset rendered_annotations(const DetectionDataset& dataset, const ImagingModel& model,
                                      int res_factor, bool distortion);

}  // namespace lensopt
