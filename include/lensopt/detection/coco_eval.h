// COCO-style average precision of object detections, as the COCO benchmark defines it (its
// published evaluation: "cocoeval"), implemented once for the joint optimization, the CLI and
// the tests.
//
// Per image I and category c, at IoU threshold t and area range A:
//  - ground truths G(I, c): a ground truth is *ignored* if it is a crowd region or its area lies
//    outside A (area < A.lo or area > A.hi);
//  - detections D(I, c): sorted by score (descending, stable), only the first max_detections kept;
//  - matching, greedy in score order: each detection takes the not-yet-matched ground truth of
//    highest IoU >= t (a crowd ground truth may be matched any number of times and its overlap is
//    intersection / detection area); a non-ignored ground truth is preferred to an ignored one:
//    once the best candidate is non-ignored, ignored ones are not considered;
//  - a detection matched to an ignored ground truth is ignored; an unmatched detection whose own
//    area lies outside A is ignored.
// Per category c, A and t: all kept detections of all images in score order (stable); with
// TP_k, FP_k the running counts of matched / unmatched non-ignored detections and n_g the number of
// non-ignored ground truths (a category with n_g = 0 has no AP and is left out of the mean):
//   recall_k = TP_k / n_g,  precision_k = TP_k / (TP_k + FP_k),
//   precision made non-increasing from the end (p_k <- max(p_k, p_{k+1})),
//   AP = mean over the 101 recall thresholds r = 0, 0.01, ..., 1 of p at the first k with
//        recall_k >= r (0 when recall never reaches r).
// AP = mean over t = 0.50, 0.55, ..., 0.95 and the categories; AP50, AP75 at one t; AP_small,
// AP_medium, AP_large over A = [0, 32^2], [32^2, 96^2], [96^2, inf) px^2 (all three with 100
// detections). AR_k = recall at the last detection with at most k detections per image, averaged
// over t and categories. A figure with no category to average is -1 (COCO's convention).
#pragma once

#include <string>
#include <vector>

#include "lensopt/detection/boxes.h"

namespace lensopt {

struct GroundTruth {
  int image = 0;  // any id shared with the detections
  int category = 0;
  Box box;
  double area = -1;  // COCO's "area" (segment area); < 0: the box's area
  bool crowd = false;
};

struct Detection {
  int image = 0;
  int category = 0;
  Box box;
  double score = 0;
};

struct CocoStats {
  double ap = -1;  // IoU 0.50:0.95, all areas, 100 detections
  double ap50 = -1;
  double ap75 = -1;
  double ap_small = -1;
  double ap_medium = -1;
  double ap_large = -1;
  double ar1 = -1;  // recall with 1, 10, 100 detections per image
  double ar10 = -1;
  double ar100 = -1;
  double ar_small = -1;
  double ar_medium = -1;
  double ar_large = -1;
  std::vector<int> categories;          // the categories evaluated (sorted)
  std::vector<double> ap_per_category;  // IoU 0.50:0.95, all areas; -1 without ground truth
  int images = 0;
  int ground_truths = 0;
  int detections = 0;
};

struct CocoEvalOptions {
  std::vector<double> iou_thresholds;  // empty: 0.50, 0.55, ..., 0.95
  int max_detections = 100;            // for AP (AR also at 1 and 10)
};

// Evaluates detections against ground truths over the images that appear in either list (and in
// `images` if it is not empty: images with no ground truth and no detection still count for AR's
// per-image limits only through their detections, so listing them changes nothing but `images`).
CocoStats evaluate_coco(const std::vector<GroundTruth>& ground_truths,
                        const std::vector<Detection>& detections,
                        const CocoEvalOptions& options = {});

// "AP 0.523  AP50 ...": one line for logs.
std::string format_coco_stats(const CocoStats& stats);

}  // namespace lensopt
