#!/usr/bin/env bash
# Benchmark of one joint optimization step (issue 7). Builds nothing: give it the lensopt
# executable.
#
#   tools/bench-joint.sh path/to/lensopt [LENS] [STEPS]
#
# Runs `lensopt optimize LENS --joint --only-joint` (default lenses/doublet.toml) for STEPS steps
# (default 6) with the issue's setting: a batch of 4 crops of 256 x 256 from the built-in
# 1280 x 720 scenes, PSFs at 21 fields and 8 rings (the joint default, imaging.h), l_lens at
# 8 rings x 11 fields, the restoration network (4 layers, 16 features), relative illumination and
# distortion on (the whole image formation; `--distortion auto` leaves the warp out for
# restoration). Prints the mean wall time of a joint step and its split: tracing (Jets: system,
# ray aiming, reference heights, RI), PSFs (KDE with Jets), rendering (forward, incl. the patch
# kernels of the first render after prepare), adjoint (imaging backward), network (the task's
# forward, backward and Adam step) and l_lens (value and gradient with Jets); target <= 2 s.
# The first step is included (FFTW plans are made then); the load average is printed since the
# machine is shared.
set -euo pipefail
lensopt="${1:?usage: tools/bench-joint.sh path/to/lensopt [LENS] [STEPS]}"
lens="${2:-lenses/doublet.toml}"
steps="${3:-6}"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

load_before=$(cut -d' ' -f1-3 /proc/loadavg)
"$lensopt" optimize "$lens" --joint --only-joint -o "$tmp/out.toml" --steps "$steps" \
  --decay-steps 0 --batch 4 --crop 256 --psf-fields 21 --psf-rings 8 --distortion on \
  --eval-crops 4 --json -q > "$tmp/report.json"
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
python3 - "$tmp/report.json" "$lens" "$load_before" "$load_after" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
t = r["step_seconds"]
cpu = "unknown CPU"
for line in open("/proc/cpuinfo"):
    if line.startswith("model name"):
        cpu = line.split(":", 1)[1].strip()
        break
import os
print(f"### One joint step: {sys.argv[2]}, batch 4 x 256 x 256, PSFs at 21 fields x 8 rings")
print(f"Machine: {os.cpu_count()} cores, {cpu}; load average before {sys.argv[3]}, after {sys.argv[4]}.")
print(f"Mean of {t['steps']} steps.\n")
print("| part | s per step | share |")
print("|---|---|---|")
for key, name in [("trace", "tracing (Jets, RI, ref. heights)"), ("psf", "PSFs (KDE, Jets)"),
                  ("render", "rendering (forward, patch kernels)"), ("adjoint", "adjoint (imaging backward)"),
                  ("network", "network (forward, backward, Adam)"), ("design_loss", "l_lens value + gradient (Jets)")]:
    print(f"| {name} | {t[key]:.3f} | {100 * t[key] / t['total']:.0f} % |")
rest = t["total"] - sum(t[k] for k in ["trace", "psf", "render", "adjoint", "network", "design_loss"])
print(f"| other (crops, Adam, log) | {rest:.3f} | {100 * rest / t['total']:.0f} % |")
print(f"| **whole step, wall** | **{t['total']:.3f}** | target <= 2 s |")
print(f"| whole step, process CPU time (all threads) | {t['total_cpu']:.3f} | |")
PY
