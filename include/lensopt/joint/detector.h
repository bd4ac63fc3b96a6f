// Object detection as the joint optimization's downstream task.
//
// Built-in detector ("detection"): a small single-stage, anchor-free detector in the manner of
// CenterNet ("Objects as Points"), sized to train on a CPU in minutes on small crops.
//   Backbone: conv3x3 + ReLU stages at strides 2, 4, 8, 16 (16, 32, 64, 64 channels, two convs
//   from stride 4 on); a top-down path upsamples stride 16 -> 8 -> 4, adding the lateral
//   features (1x1 convs) of the same stride.
//   Heads at stride S = 4, from 32 channels: a heat map per class (sigmoid; bias initialised to
//   log(0.1 / 0.9) so the untrained map predicts 0.1), the box size (log(w / S), log(h / S)) and
//   the sub-cell centre offset.
//   Targets: each ground-truth box (crowd regions excepted) puts a Gaussian bump exp(-d^2 / (2
//   sigma^2)) at its centre cell c = floor(centre / S) in its class's map (sigma = (2 r + 1) / 6, r
//   = 0.3 min(w, h) / S; the maximum where bumps overlap; exactly 1 at c), its size and offset at
//   c. Loss: the penalty-reduced focal loss over every map cell (alpha = 2, beta = 4) divided by
//   the number of objects, plus L1 of the size and of the offset at the centre cells, also divided
//   by the number of objects. The mean over the batch is the task's loss. Detections: heat-map
//   peaks (a cell equal to the maximum of its 3 x 3 neighbourhood), the best 100 per image over all
//   classes, box = (c + offset) S -+ exp(size) S / 2, score = heat. Metric: COCO AP
//   (detection/coco_eval.h) of a batch's detections, after the correction the caller applies (the
//   joint loop un-distorts predicted boxes before evaluation).
//
// TorchScript detectors ("torchscript:MODEL.pt" whose forward takes three tensors):
//   forward(images, boxes, labels)
//     images: B x C x H x W, float32 (float64 with double precision), values ~[0, 1];
//     boxes:  B x N x 4, float32: (x0, y0, x1, y1) in the image's pixels (detection/boxes.h),
//             N = the largest box count of the batch, padded with zeros;
//     labels: B x N, int64: class ids 1..K, -1 for padding rows.
//   In training mode (module.train()) it returns the scalar loss, the mean over the batch; in
//   evaluation mode (module.eval()) it returns B x M x 6, float: (x0, y0, x1, y1, score, label)
//   per detection, rows with score <= 0 being padding. lensopt trains the parameters that require
//   a gradient with Adam and calls eval()/train() around evaluation.
//   tools/export-retinanet.py writes torchvision's RetinaNet-ResNet50 under this contract.
#pragma once

#include <memory>

#include "lensopt/joint/task.h"

namespace lensopt {

// The detector's class count: the paper's six (detection/dataset.h).
constexpr int kDetectorClasses = 6;

// Whether a TorchScript file's forward takes (images, boxes, labels). Throws Error if the file
// cannot be loaded or libtorch is not available (require_torch in task.h).
bool is_torchscript_detector(const std::filesystem::path& model);

}  // namespace lensopt
