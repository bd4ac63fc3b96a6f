#!/usr/bin/env bash
# Benchmark of one joint detection step (issue 19). Builds nothing: give it the lensopt
# executable.
#
#   tools/bench-joint-detection.sh path/to/lensopt [LENS] [STEPS] [THREADS]
#
# Generates 8 driving scenes of 640 x 360 (`lensopt chart --detection`), then runs
# `lensopt optimize LENS --joint --task detection --only-joint` (default lenses/doublet.toml) for
# STEPS steps (default 6) with the issue's setting: a batch of 4 crops of 256 x 256 with their
# boxes, PSFs at 21 fields and 8 rings, the 2x resolution factor, relative illumination and
# distortion on (boxes distorted as the images), the built-in detector, l_lens at 8 rings x 11
# fields. The perfect-optics detector is trained first (2 x STEPS network-only steps, not timed).
# Prints the mean wall time of a joint step and its split: tracing (Jets: system, ray aiming,
# reference heights, RI), PSFs (KDE with Jets), rendering (forward, incl. the patch kernels of
# the first render after prepare, and the boxes), adjoint (imaging backward), network (the
# detector's forward, backward and Adam step) and l_lens (value and gradient); target <= 1 s.
# The first step is included (FFTW plans are made then); the load average is printed since the
# machine is shared. THREADS (default 0: all cores) is passed as --threads.
set -euo pipefail
lensopt="${1:?usage: tools/bench-joint-detection.sh path/to/lensopt [LENS] [STEPS] [THREADS]}"
lens="${2:-lenses/doublet.toml}"
steps="${3:-6}"
threads="${4:-0}"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

"$lensopt" chart --detection -o "$tmp/data" --count 8 --size 640x360 --seed 1 > /dev/null
load_before=$(cut -d' ' -f1-3 /proc/loadavg)
"$lensopt" optimize "$lens" --joint --task detection --data "$tmp/data" --only-joint \
  -o "$tmp/out.toml" --steps "$steps" --decay-steps 0 --batch 4 --crop 256 --psf-fields 21 \
  --psf-rings 8 --res-factor 2 --eval-crops 4 --threads "$threads" --json -q > "$tmp/report.json"
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
python3 - "$tmp/report.json" "$lens" "$load_before" "$load_after" "$threads" <<'PY'
import json, os, sys
r = json.load(open(sys.argv[1]))
t = r["step_seconds"]
cpu = "unknown CPU"
for line in open("/proc/cpuinfo"):
    if line.startswith("model name"):
        cpu = line.split(":", 1)[1].strip()
        break
print(f"### One joint detection step: {sys.argv[2]}, batch 4 x 256 x 256, 2x, PSFs at 21 fields x 8 rings, --threads {sys.argv[5]}")
print(f"Machine: {os.cpu_count()} cores, {cpu}; load average before {sys.argv[3]}, after {sys.argv[4]}.")
print(f"Mean of {t['steps']} steps.\n")
print("| part | s per step | share |")
print("|---|---|---|")
for key, name in [("trace", "tracing (Jets, RI, ref. heights)"), ("psf", "PSFs (KDE, Jets)"),
                  ("render", "rendering (forward, patch kernels, boxes)"), ("adjoint", "adjoint (imaging backward)"),
                  ("network", "detector (forward, backward, Adam)"), ("design_loss", "l_lens value + gradient")]:
    print(f"| {name} | {t[key]:.3f} | {100 * t[key] / t['total']:.0f} % |")
rest = t["total"] - sum(t[k] for k in ["trace", "psf", "render", "adjoint", "network", "design_loss"])
print(f"| other (crops, Adam, log) | {rest:.3f} | {100 * rest / t['total']:.0f} % |")
print(f"| **whole step, wall** | **{t['total']:.3f}** | target <= 1 s |")
print(f"| whole step, process CPU time (all threads) | {t['total_cpu']:.3f} | |")
PY
