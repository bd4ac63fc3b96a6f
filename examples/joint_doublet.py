#!/usr/bin/env python3
"""Joint optimization of the Doublet and a restoration network in a plain PyTorch loop.

    PYTHONPATH=build/python python3 examples/joint_doublet.py --steps 200

The paper's three settings on the same data stream (the scene generator and the network's
initialization restart from the seed for each), scored by PSNR on held-out crops:
    fixed/fixed    the start lens, the untrained network (the identity: it is residual with a
                   zero last layer)
    fixed/trained  the start lens, the network trained for all steps
    joint          lens variables and network trained together:
                   l_joint = MSE(net(optics(scene)), scene) + lambda_lens l_lens(x)
The optics are lensopt.torch.ImageFormation (PSF blur, relative illumination and distortion with
exact lens gradients); l_lens is the paper's lens loss (spot, ray path, ray angle, glass terms).
Scenes are synthetic (rectangles, disks and stripes on smooth backgrounds), rendered as crops of
a larger sensor image so that the PSFs span pixels.
"""

import argparse
import math
import sys
import time
from pathlib import Path

import torch
from torch import nn

import lensopt
import lensopt.torch as lt

ROOT = Path(__file__).resolve().parents[1]


def scenes(generator, count, width, height):
    """`count` synthetic linear-light scenes, count x 3 x height x width in [0, 1]."""
    ys = torch.linspace(0, 1, height).view(1, height, 1)
    xs = torch.linspace(0, 1, width).view(1, 1, width)
    out = []
    for _ in range(count):
        rnd = lambda *s: torch.rand(*s, generator=generator)  # noqa: E731
        img = rnd(3, 1, 1) * 0.5 + 0.5 * rnd(3, 1, 1) * xs + 0.3 * rnd(3, 1, 1) * ys
        for _ in range(12):
            x0, y0, w, h = rnd(4) * torch.tensor([1.0, 1.0, 0.3, 0.3])
            mask = ((xs >= x0) & (xs < x0 + w) & (ys >= y0) & (ys < y0 + h)).float()
            img = img * (1 - mask) + rnd(3, 1, 1) * mask
        for _ in range(4):
            cx, cy, r = rnd(3) * torch.tensor([1.0, 1.0, 0.15])
            mask = (((xs - cx) ** 2 + (ys - cy) ** 2) < r * r).float()
            img = img * (1 - mask) + rnd(3, 1, 1) * mask
        freq, angle = 20 + 60 * rnd(1), math.pi * rnd(1)
        stripes = 0.5 + 0.5 * torch.sin(2 * math.pi * freq * (xs * torch.cos(angle) + ys * torch.sin(angle)))
        sx, sy = rnd(2) * 0.7
        mask = ((xs >= sx) & (xs < sx + 0.3) & (ys >= sy) & (ys < sy + 0.3)).float()
        img = img * (1 - mask) + stripes * mask
        out.append(img.clamp(0, 1))
    return torch.stack(out)


class Restorer(nn.Module):
    """A small residual CNN; the zero last layer makes it the identity at initialization."""

    def __init__(self, width=16):
        super().__init__()
        self.body = nn.Sequential(
            nn.Conv2d(3, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(width, 3, 3, padding=1))
        nn.init.zeros_(self.body[-1].weight)
        nn.init.zeros_(self.body[-1].bias)

    def forward(self, x):
        return x + self.body(x)


def psnr(a, b):
    mse = ((a - b) ** 2).mean().item()
    return 10 * math.log10(1.0 / max(mse, 1e-12))


def run_setting(name, args, train_lens, train_net):
    generator = torch.Generator().manual_seed(args.seed)
    torch.manual_seed(args.seed)
    lens = lensopt.load_lens(str(args.lens))
    optics = lt.ImageFormation(lens, rings=args.rings, threads=args.threads)
    optics.x.requires_grad_(train_lens)
    net = Restorer()
    groups = []
    if train_net:
        groups.append({"params": net.parameters(), "lr": args.net_lr})
    if train_lens:
        groups.append({"params": [optics.x], "lr": args.lens_lr})
    optimizer = torch.optim.Adam(groups) if groups else None
    w, h, c = args.scene_width, args.scene_height, args.crop
    held_out = scenes(torch.Generator().manual_seed(args.seed + 1000), args.held_out, w, h)
    start = time.time()
    for step in range(args.steps if optimizer else 0):
        sharp = scenes(generator, args.batch, w, h)
        x0 = int(torch.randint(0, w - c + 1, (1,), generator=generator))
        y0 = int(torch.randint(0, h - c + 1, (1,), generator=generator))
        crop = (x0, y0, c, c)
        target = sharp[:, :, y0:y0 + c, x0:x0 + c]
        loss = ((net(optics(sharp, crop)) - target) ** 2).mean()
        if train_lens:
            loss = loss + args.lambda_lens * optics.lens_loss()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if args.verbose and (step % 10 == 0 or step == args.steps - 1):
            print(f"  {name} step {step}: loss {loss.item():.5f}", file=sys.stderr)
    # Held-out PSNR on fixed crops (the centre and a corner of each held-out scene).
    with torch.no_grad():
        values = []
        for crop in ((w // 2 - c // 2, h // 2 - c // 2, c, c), (0, 0, c, c)):
            x0, y0 = crop[0], crop[1]
            restored = net(optics(held_out, crop)).clamp(0, 1)
            values.append(psnr(restored, held_out[:, :, y0:y0 + c, x0:x0 + c]))
    spot = optics.lens_loss_terms()[0].item() * 1000
    return {"setting": name, "psnr_db": sum(values) / len(values), "spot_um": spot,
            "glasses": optics.glasses(), "seconds": time.time() - start}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--lens", default=ROOT / "lenses" / "doublet.toml", type=Path)
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--scene-width", type=int, default=640)
    p.add_argument("--scene-height", type=int, default=360)
    p.add_argument("--crop", type=int, default=96)
    p.add_argument("--held-out", type=int, default=8)
    p.add_argument("--rings", type=int, default=8)
    p.add_argument("--lens-lr", type=float, default=5e-3)
    p.add_argument("--net-lr", type=float, default=1e-3)
    p.add_argument("--lambda-lens", type=float, default=1.0)
    p.add_argument("--threads", type=int, default=0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--settings", default="fixed/fixed,fixed/trained,joint",
                   help="which settings to run (comma-separated; e.g. one per process)")
    p.add_argument("--verbose", action="store_true")
    args = p.parse_args(argv)

    flags = {"fixed/fixed": (False, False), "fixed/trained": (False, True), "joint": (True, True)}
    names = [n.strip() for n in args.settings.split(",") if n.strip()]
    for n in names:
        if n not in flags:
            p.error(f"unknown setting {n!r} (known: {', '.join(flags)})")
    results = [run_setting(n, args, *flags[n]) for n in names]
    print("| setting | held-out PSNR (dB) | mean spot (um) | glasses | seconds |")
    print("|---|---|---|---|---|")
    for r in results:
        print(f"| {r['setting']} | {r['psnr_db']:.2f} | {r['spot_um']:.2f} | "
              f"{', '.join(r['glasses'])} | {r['seconds']:.0f} |")
    return results


if __name__ == "__main__":
    main()
