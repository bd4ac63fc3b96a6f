#!/usr/bin/env bash
# Benchmark of lensopt.torch.ImageFormation (issue 20) against the CLI's joint imaging step.
#
#   tools/bench-python.sh [build-dir] [threads]
#
# Python: forward + backward of the module for a batch of 4 x 3 x 256 x 256 float32 images on the
# CPU (the Doublet, quantized glasses, RI and distortion on, 8 rings x 21 fields: the joint
# optimization's sampling), gradients wrt the lens variables only (as the CLI's step) and also
# wrt the images. CLI: `lensopt bench --joint-imaging` (prepare + render + backward of 4 crops of
# 256 x 256). Median of 5 after a warm-up. Prints a Markdown table with the load average.
set -euo pipefail
build="${1:-build}"
threads="${2:-2}"
root="$(cd "$(dirname "$0")/.." && pwd)"
python="${PYTHON:-/usr/bin/python3}"
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
cli=$("$build/lensopt" bench --joint-imaging --json --repeats 5 --rings 8 --threads "$threads" \
  --lens "$root/lenses/doublet.toml")
py=$(PYTHONPATH="$build/python" OMP_NUM_THREADS="$threads" "$python" - "$root" "$threads" <<'PY'
import json, statistics, sys, time
import torch
import lensopt, lensopt.torch as lt
root, threads = sys.argv[1], int(sys.argv[2])
torch.set_num_threads(threads)
module = lt.ImageFormation(lensopt.load_lens(root + "/lenses/doublet.toml"), threads=threads)
images = torch.rand(4, 3, 256, 256)
def step(image_grad):
    module.x.grad = None
    # A new x each step, as in training: the optics are sampled again.
    with torch.no_grad():
        module.x[0] += 1e-9
    imgs = images.clone().requires_grad_(image_grad)
    t0 = time.perf_counter()
    out = module(imgs)
    t1 = time.perf_counter()
    out.square().mean().backward()
    t2 = time.perf_counter()
    return t1 - t0, t2 - t1
res = {}
for image_grad in (False, True):
    step(image_grad)
    runs = [step(image_grad) for _ in range(5)]
    res[image_grad] = (statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs),
                       statistics.median(r[0] + r[1] for r in runs))
print(json.dumps({str(k): v for k, v in res.items()}))
PY
)
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
"$python" - "$cli" "$py" "$threads" "$load_before" "$load_after" <<'PY'
import json, sys
cli, py = json.loads(sys.argv[1]), json.loads(sys.argv[2])
threads, before, after = sys.argv[3:6]
print(f"| what | forward (ms) | backward (ms) | step (ms) |")
print("|---|---|---|---|")
print(f"| CLI joint imaging step (prepare + render + backward, 4 crops 256^2) | "
      f"{cli['prepare_ms'] + cli['render_4_crops_ms']:.0f} | {cli['backward_4_crops_ms']:.0f} | "
      f"{cli['step_ms']:.0f} |")
for key, label in (("False", "lens variables"), ("True", "lens variables and images")):
    f, b, s = py[key]
    print(f"| lensopt.torch.ImageFormation, 4 x 3 x 256 x 256, grad wrt {label} | {f * 1e3:.0f} | "
          f"{b * 1e3:.0f} | {s * 1e3:.0f} |")
print(f"\nthreads {threads}; load average before {before}, after {after}")
PY
