// Object detection as the joint optimization's downstream task.
//
// Built-in detector ("detection"): a small single-stage, anchor-free detector in the manner of
// CenterNet ("Objects as Points") with FCOS-style levels, sized to train on a CPU in minutes on
// small crops.
//   Backbone: conv3x3 -> GroupNorm (8 groups) -> ReLU throughout (batch-size independent, the same
//   in training and evaluation); stages at strides 2, 4, 8, 16, 32 of 16, 32, 64, 96, 128
//   channels (one stride-2 conv, then one more conv from stride 4 on).
//   Pyramid: 1x1 lateral convs to 64 channels at strides 4, 8, 16, 32; top-down, each level adds
//   the nearest-upsampled level above it (P16 = L16 + up(L32), P8 = L8 + up(P16), P4 = L4 +
//   up(P8)).
//   Heads at strides S = 4, 8, 16, sharing their weights: conv3x3 + GroupNorm + ReLU (64
//   channels), then 1x1 convs to a heat map per class (sigmoid), the box size (log(w / S),
//   log(h / S)) and the sub-cell centre offset. The output convs start with weights N(0, 0.01^2)
//   and biases log(0.1 / 0.9) (heat 0.1: the focal loss's prior), log 4 (a box of 4 x 4 cells)
//   and 0.5 (the cell's centre).
//   Assignment by size: a box whose longer side is m pixels is trained at stride 4 if m < 32,
//   at stride 8 if 32 <= m < 64, at stride 16 otherwise (2 to 8 cells a side at its level,
//   larger boxes above).
//   Targets, at the box's level: a Gaussian bump exp(-d^2 / (2 sigma^2)) at its centre cell c =
//   floor(centre / S) in its class's map (sigma = (2 r + 1) / 6, r = 0.3 min(w, h) / S; the
//   maximum where bumps overlap; exactly 1 at c), its size and offset at c. Loss: over every
//   level, the penalty-reduced focal loss over every map cell (alpha = 2, beta = 4) plus L1 of
//   the size and of the offset at the centre cells, all divided by the number of objects over all
//   levels; the mean over the batch is the task's loss. Training: Adam, the learning rate of the
//   schedule times min(1, k / 100) at the detector's k-th Adam step (a warm-up of a fresh
//   detector; a loaded one continues its count). Detections: at each level the heat-map peaks (a
//   cell equal to the maximum of its 3 x 3 neighbourhood), the best 100 per image over all
//   classes, box = (c + offset) S -+ exp(size) S / 2, score = heat; over the levels, by falling
//   score, a detection is dropped when it overlaps a kept one of the same class from another
//   level with IoU > 0.6 (one object seen at two strides), and the best 100 per image are kept.
//   Image sides must be multiples of 16. Metric: COCO AP (detection/coco_eval.h) of a batch's
//   detections, after the correction the caller applies (the joint loop un-distorts predicted
//   boxes before evaluation). State files (the network, Adam, "detector_version" = 2) of the
//   earlier detector (plain conv + ReLU, one stride-4 head: version 1) are refused with an error
//   that says to train the detector again.
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
