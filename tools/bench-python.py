#!/usr/bin/env python3
"""Overhead of lensopt.torch.ImageFormation against the CLI's joint imaging step (issue 20).

    PYTHONPATH=build/python /usr/bin/python3 tools/bench-python.py [--build build] [--threads 2]

CLI: `lensopt bench --joint-imaging` (the Doublet, quantized glasses, RI and distortion on, 21
fields x 8 rings): prepare (Jet optics) + render + backward of 4 crops of 256 x 256 from a
1280 x 720 chart, the gradient wrt the lens variables. Python, the same optics and sampling, on
the CPU, float32 images, forward + backward of a loss wrt x (and optionally the images), a new x
each step so the optics are sampled again:
  - "4 crops": the CLI's work: a 1 x 3 x 720 x 1280 scene, the same four 256 x 256 crops;
  - "batch 4 x 256^2": a batch of four 3 x 256 x 256 full images (smaller PSFs in pixels).
Median of --repeats after a warm-up. Prints a Markdown table with the load average, the wall
times and the process's CPU time per step (time.process_time: all threads, user + system; on a
shared machine the wall time counts the waits for a core, the CPU time does not). The CLI's
step CPU time is its own (`step_cpu_ms`, the same clock).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CROPS = [(0, 0, 256, 256), (512, 232, 256, 256), (1024, 464, 256, 256), (300, 380, 256, 256)]


def load():
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--build", default=str(ROOT / "build"))
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--lens", default=str(ROOT / "lenses" / "doublet.toml"))
    args = p.parse_args()
    sys.path.insert(0, str(Path(args.build) / "python"))
    import torch

    import lensopt
    import lensopt.torch as lt

    torch.set_num_threads(args.threads)
    before = load()
    cli = json.loads(subprocess.run(
        [str(Path(args.build) / "lensopt"), "bench", "--joint-imaging", "--json", "--repeats",
         str(args.repeats), "--rings", "8", "--threads", str(args.threads), "--lens", args.lens],
        check=True, capture_output=True, text=True).stdout)

    module = lt.ImageFormation(lensopt.load_lens(args.lens), threads=args.threads)
    gen = torch.Generator().manual_seed(0)
    scene = torch.rand(1, 3, 720, 1280, generator=gen)
    batch = torch.rand(4, 3, 256, 256, generator=gen)
    weights = torch.randn(4, 3, 256, 256, generator=gen) * 1e-3

    def step(kind, image_grad):
        module.x.grad = None
        with torch.no_grad():  # a new x each step, as in training: the optics are sampled again
            module.x[0] += 1e-9
        c0 = time.process_time()
        t0 = time.perf_counter()
        if kind == "crops":
            s = scene.clone().requires_grad_(image_grad)
            outs = [module(s, c) for c in CROPS]
            t1 = time.perf_counter()
            loss = sum((o[0] * w).sum() for o, w in zip(outs, weights))
        else:
            b = batch.clone().requires_grad_(image_grad)
            out = module(b)
            t1 = time.perf_counter()
            loss = (out * weights).sum()
        loss.backward()
        t2 = time.perf_counter()
        return t1 - t0, t2 - t1, t2 - t0, time.process_time() - c0

    rows = []
    for kind, label in (("crops", "4 crops 256^2 of 1 x 3 x 720 x 1280 (the CLI's work)"),
                        ("batch", "batch 4 x 3 x 256 x 256")):
        for image_grad in (False, True):
            step(kind, image_grad)
            runs = [step(kind, image_grad) for _ in range(args.repeats)]
            med = [statistics.median(r[i] for r in runs) * 1e3 for i in range(4)]
            what = "x and images" if image_grad else "x"
            rows.append((f"lensopt.torch, {label}, grad wrt {what}", *med))
    after = load()
    cli_step, cli_cpu = cli["step_ms"], cli["step_cpu_ms"]
    print("| what | forward (ms) | backward (ms) | step (ms) | / CLI step | step CPU (ms) "
          "| / CLI step CPU |")
    print("|---|---|---|---|---|---|---|")
    print(f"| CLI joint imaging step (prepare {cli['prepare_ms']:.0f} + render "
          f"{cli['render_4_crops_ms']:.0f}; backward of 4 crops) | "
          f"{cli['prepare_ms'] + cli['render_4_crops_ms']:.0f} | "
          f"{cli['backward_4_crops_ms']:.0f} | {cli_step:.0f} | 1.00 | {cli_cpu:.0f} | 1.00 |")
    for label, f, b, s, c in rows:
        print(f"| {label} | {f:.0f} | {b:.0f} | {s:.0f} | {s / cli_step:.2f} | {c:.0f} | "
              f"{c / cli_cpu:.2f} |")
    print(f"\nthreads {args.threads} (torch and C++), median of {args.repeats}; "
          f"{os.cpu_count()} cores; load average before {before}, after {after}")


if __name__ == "__main__":
    main()
