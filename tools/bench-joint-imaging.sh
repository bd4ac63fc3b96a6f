#!/usr/bin/env bash
# Benchmark of the joint optimization's differentiable imaging (issue 7). Builds nothing: give it
# the lensopt executable.
#
#   tools/bench-joint-imaging.sh path/to/lensopt [RINGS]
#
# For the Doublet and the Tessar (quantized glasses, RI and distortion on): prepare() at 21 PSF
# fields with RINGS pupil rings (default 8: 64 rays per field and wavelength, x 15 wavelengths),
# split into the Jet trace (system, aiming, RI) and the Jet PSFs; then render + backward of a
# batch of four 256 x 256 crops of a 1280 x 720 chart. Median of 5. Prints a Markdown section
# for BENCHMARKS.md with the machine (nproc, CPU model) and the load average, which matters on a
# shared machine.
set -euo pipefail
lensopt="${1:?usage: tools/bench-joint-imaging.sh path/to/lensopt [RINGS]}"
rings="${2:-8}"
root="$(cd "$(dirname "$0")/.." && pwd)"

load_before=$(cut -d' ' -f1-3 /proc/loadavg)
rows=""
for lens in doublet tessar; do
  for threads in 2 1; do
    json=$("$lensopt" bench --joint-imaging --json --repeats 5 --rings "$rings" \
      --threads "$threads" --lens "$root/lenses/$lens.toml")
    rows+=$(python3 -c '
import json, sys
j = json.loads(sys.argv[1])
print("| {lens} | {variables} | {threads} | {prepare_ms:.0f} ms ({trace_ms:.0f} + {psf_ms:.0f}) | "
      "{prepare_values_only_ms:.0f} ms | "
      "{render_4_crops_ms:.0f} ms | {backward_4_crops_ms:.0f} ms | {step_ms:.0f} ms | "
      "{step_cpu_ms:.0f} ms |".format(**j))
' "$json")$'\n'
  done
done
load_after=$(cut -d' ' -f1-3 /proc/loadavg)
cpu=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')

cat <<MD
## Joint imaging (issue 7)

\`tools/bench-joint-imaging.sh build/lensopt $rings\`: \`DifferentiableImaging\` (joint/imaging.h)
with quantized glasses, relative illumination and distortion on. prepare(): 21 PSF fields x
$rings rings ($((rings * rings)) rays per field and wavelength, 15 wavelengths), Jets with one
derivative per lens variable; "trace" is the system, ray aiming, reference heights and RI, "PSF"
the traced KDE PSFs. Then render + backward of four 256 x 256 crops of a 1280 x 720 chart (the
first render after prepare() also builds the 81 patch kernels; backward reuses the render's
blurred region; "values only" is prepare(x, false), for evaluation). Median of 5; "CPU" is the process CPU time of the step (all threads).

| lens | variables | threads | prepare (trace + PSF) | prepare, values only | render, 4 crops | backward, 4 crops | whole step, wall | whole step, CPU |
|---|---|---|---|---|---|---|---|---|---|
$rows
Machine: $(nproc) cores, $cpu; load average $load_before before, $load_after after (the
machine is shared with other builds and runs).
MD
