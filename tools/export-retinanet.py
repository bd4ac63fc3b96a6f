#!/usr/bin/env python3
"""Export torchvision's RetinaNet-ResNet50-FPN as a TorchScript detector for lensopt.

The module follows the detection contract of include/lensopt/joint/detector.h:

    forward(images, boxes, labels)
      images: B x 3 x H x W float, values ~[0, 1]
      boxes:  B x N x 4 float, (x0, y0, x1, y1) pixels, padded rows
      labels: B x N int64, class ids 1..K, -1 for padding
    training mode:   the scalar loss (RetinaNet's classification + box regression losses)
    evaluation mode: B x M x 6 (x0, y0, x1, y1, score, label), rows with score <= 0 are padding

Usage (Debian: apt-get install python3-torchvision):
    tools/export-retinanet.py -o retinanet.pt [--classes 6] [--weights FILE.pth]
        [--backbone-weights FILE.pth] [--min-size 256] [--max-size 512]

Without weight files the network starts from random weights (this machine reaches no model hub);
give --backbone-weights (an ImageNet ResNet-50 state dict) or --weights (a full RetinaNet state
dict) for the paper's setting. Then train it jointly with a lens:
    lensopt optimize LENS --joint --task torchscript:retinanet.pt ...
"""
import argparse
import sys
from typing import Dict, List, Tuple

import torch
from torch import Tensor, nn

try:
    import torchvision
    from torchvision.models.detection import retinanet_resnet50_fpn
except ImportError:  # pragma: no cover - reported to the user
    sys.exit("export-retinanet: torchvision is not installed (apt-get install python3-torchvision)")


def nms_torchscript(boxes: Tensor, scores: Tensor, iou_threshold: float) -> Tensor:
    """Greedy non-maximum suppression in plain TorchScript (torchvision's own nms is a C++ op that
    lensopt's libtorch does not have): the indices of the kept boxes, by decreasing score."""
    order = torch.argsort(scores, descending=True)
    areas = (boxes[:, 2] - boxes[:, 0]).clamp(min=0) * (boxes[:, 3] - boxes[:, 1]).clamp(min=0)
    suppressed = torch.zeros(boxes.size(0), dtype=torch.bool, device=boxes.device)
    keep: List[int] = []
    for k in range(order.size(0)):
        i = int(order[k])
        if bool(suppressed[i]):
            continue
        keep.append(i)
        w = (torch.min(boxes[i, 2], boxes[:, 2]) - torch.max(boxes[i, 0], boxes[:, 0])).clamp(min=0)
        h = (torch.min(boxes[i, 3], boxes[:, 3]) - torch.max(boxes[i, 1], boxes[:, 1])).clamp(min=0)
        inter = w * h
        iou = inter / (areas[i] + areas - inter).clamp(min=1e-12)
        suppressed = suppressed | (iou > iou_threshold)
    return torch.tensor(keep, dtype=torch.int64, device=boxes.device)


# RetinaNet's post-processing reaches torchvision.ops.boxes.nms through batched_nms; scripting
# then resolves the module global, so the exported file needs no torchvision C++ op.
torchvision.ops.boxes.nms = nms_torchscript


class LensoptDetector(nn.Module):
    """RetinaNet behind lensopt's (images, boxes, labels) contract."""

    def __init__(self, model: nn.Module, max_detections: int):
        super().__init__()
        self.model = model
        self.max_detections = max_detections

    def forward(self, images: Tensor, boxes: Tensor, labels: Tensor) -> Tensor:
        image_list: List[Tensor] = [images[i] for i in range(images.size(0))]
        if self.training:
            targets: List[Dict[str, Tensor]] = []
            for i in range(images.size(0)):
                keep = labels[i] >= 0
                targets.append({"boxes": boxes[i][keep].to(images.dtype),
                                "labels": labels[i][keep].to(torch.int64)})
            losses, _ = self.model(image_list, targets)
            total = torch.zeros((), dtype=images.dtype, device=images.device)
            for value in losses.values():
                total = total + value
            return total
        _, detections = self.model(image_list, None)
        out = torch.zeros((images.size(0), self.max_detections, 6), dtype=images.dtype,
                          device=images.device)
        for i, d in enumerate(detections):
            n = min(d["boxes"].size(0), self.max_detections)
            out[i, :n, 0:4] = d["boxes"][:n].to(images.dtype)
            out[i, :n, 4] = d["scores"][:n].to(images.dtype)
            out[i, :n, 5] = d["labels"][:n].to(images.dtype)
        return out


def build(classes: int, min_size: int, max_size: int, weights: str, backbone_weights: str,
          max_detections: int) -> torch.jit.ScriptModule:
    model = retinanet_resnet50_fpn(weights=None, weights_backbone=None,
                                   num_classes=classes + 1, min_size=min_size,
                                   max_size=max_size, detections_per_img=max_detections)
    if backbone_weights:
        state = torch.load(backbone_weights, map_location="cpu")
        missing, _ = model.backbone.body.load_state_dict(state, strict=False)
        print(f"backbone weights: {len(state) - len(missing)} tensors loaded", file=sys.stderr)
    if weights:
        model.load_state_dict(torch.load(weights, map_location="cpu"))
    wrapper = LensoptDetector(model, max_detections)
    wrapper.train()
    return torch.jit.script(wrapper)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-o", "--output", required=True, help="TorchScript file to write")
    p.add_argument("--classes", type=int, default=6, help="object classes (default: the paper's 6)")
    p.add_argument("--weights", default="", help="a RetinaNet state dict (.pth)")
    p.add_argument("--backbone-weights", default="", help="a ResNet-50 state dict (.pth)")
    p.add_argument("--min-size", type=int, default=256, help="RetinaNet's resize: shorter side")
    p.add_argument("--max-size", type=int, default=512, help="RetinaNet's resize: longer side")
    p.add_argument("--max-detections", type=int, default=100)
    a = p.parse_args()
    if a.classes < 1:
        p.error("--classes must be at least 1")
    scripted = build(a.classes, a.min_size, a.max_size, a.weights, a.backbone_weights,
                     a.max_detections)
    scripted.save(a.output)
    print(f"wrote {a.output} (RetinaNet-ResNet50-FPN, {a.classes} classes, torchvision "
          f"{torchvision.__version__})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
