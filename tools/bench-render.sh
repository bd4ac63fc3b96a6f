#!/usr/bin/env bash
# Benchmark of `lensopt render` (issues 4 and 18). Builds nothing: give it the lensopt executable.
#
#   tools/bench-render.sh path/to/lensopt [LENS]
#
# Measures, at the paper's full sampling (32 rings, 21 fields, 15 wavelengths), with LENS
# (default lenses/cooke.toml):
#   - one 1280 x 720 RGB PNG at 1x, the whole command (start-up, lens, PSF sampling, render,
#     metrics, writing): best and median wall time of 5 runs;  target <= 0.3 s idle (issue 18)
#   - the same at 2x;
#   - a folder of 100 such images;                               target <= 8 s idle (issue 18)
#     with images per second per core and the time BDD100K's 80k images would take;
#   - the peak memory (maximum resident set) of the 1x run, /usr/bin/time -v;   target <= 1 GiB
# and PSNR / SSIM of the three baselines on ../shared/data/images/sample_image.png at 1x and 2x
# (skipped without ../shared). The test image is that photo resized to 1280 x 720 when ../shared
# is there, else the built-in chart. Prints a Markdown section for BENCHMARKS.md with the machine
# (nproc, CPU model) and the load average, which matters on a shared machine.
set -euo pipefail
lensopt="${1:?usage: tools/bench-render.sh path/to/lensopt [LENS]}"
lens="${2:-lenses/cooke.toml}"
shared="${LENSOPT_SHARED_DIR:-../shared}"
sample="$shared/data/images/sample_image.png"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The 1280 x 720 test image.
if [ -f "$sample" ] && command -v oiiotool > /dev/null; then
  oiiotool "$sample" --resize 1280x720 -o "$tmp/image.png"
  image_kind="sample_image.png resized to 1280x720 (8-bit RGB PNG)"
else
  "$lensopt" chart -o "$tmp/image.png" --size 1280x720 > /dev/null
  image_kind="the built-in chart, 1280x720 (8-bit RGB PNG)"
fi

# Wall and CPU (user + system) seconds of one command, with /usr/bin/time: "wall cpu".
wall_cpu() {
  /usr/bin/time -f "%e %U %S" -o "$tmp/time.txt" "$@" > /dev/null 2> "$tmp/stderr.txt" || {
    cat "$tmp/stderr.txt" >&2
    return 1
  }
  awk '{printf "%.2f %.2f\n", $1, $2 + $3}' "$tmp/time.txt"
}
# best and median wall time of 5 runs, and the median CPU time
best_median() {
  local runs=()
  for _ in 1 2 3 4 5; do runs+=("$(wall_cpu "$@")"); done
  local cpu
  cpu=$(printf '%s\n' "${runs[@]}" | awk '{print $2}' | sort -g | sed -n 3p)
  printf '%s\n' "${runs[@]}" | sort -g | awk -v cpu="$cpu" '{a[NR]=$1} END {printf "%.2f s (median %.2f s) | %.2f s", a[1], a[3], cpu}'
}

load_before=$(cut -d' ' -f1-3 /proc/loadavg)
one_1x=$(best_median "$lensopt" render "$lens" "$tmp/image.png" -o "$tmp/out1" --force -q)
one_2x=$(best_median "$lensopt" render "$lens" "$tmp/image.png" -o "$tmp/out2" --force -q --res-factor 2)
/usr/bin/time -v -o "$tmp/mem.txt" "$lensopt" render "$lens" "$tmp/image.png" -o "$tmp/out3" --force -q > /dev/null
peak_kb=$(awk -F: '/Maximum resident set size/ {gsub(/ /, "", $2); print $2}' "$tmp/mem.txt")
mkdir -p "$tmp/dir"
for i in $(seq -w 1 100); do cp "$tmp/image.png" "$tmp/dir/image_$i.png"; done
/usr/bin/time -f "%e %U %S %M" -o "$tmp/dirtime.txt" "$lensopt" render "$lens" "$tmp/dir" -o "$tmp/outdir" -q > /dev/null
dir_1x=$(awk '{printf "%.1f s | %.1f s", $1, $2 + $3}' "$tmp/dirtime.txt")
dir_peak_mib=$(awk '{printf "%d", $4 / 1024}' "$tmp/dirtime.txt")
# Throughput: images per second of wall time, per core, and 80,000 images on one machine like this.
per_core=$(awk -v n="$(nproc)" '{printf "%.2f images/s (%.2f per core); 80k images: %.1f h on one such machine", 100 / $1, 100 / $1 / n, 80000 * $1 / 100 / 3600}' "$tmp/dirtime.txt")
rm -rf "$tmp/outdir"
load_after=$(cut -d' ' -f1-3 /proc/loadavg)

cpu=$(awk -F': ' '/model name/ {print $2; exit}' /proc/cpuinfo)
echo "## Render (issues 4 and 18): $(basename "$(dirname "$(dirname "$(realpath "$lensopt")")")")"
echo
echo "Machine: $(nproc) cores, $cpu; load average ${load_before} before, ${load_after} after"
echo "(the machine is shared with other jobs). $(date -u +%Y-%m-%d), \`tools/bench-render.sh\`,"
echo "lens \`$lens\`, full paper sampling (32 rings = 2048 rays, 21 fields, 15 wavelengths);"
echo "image: $image_kind. Times are the whole command (process start, lens, PSF sampling, render,"
echo "PSNR/SSIM, writing)."
echo
echo "| measurement | wall, best of 5 (median) | CPU (user + sys) | target |"
echo "|---|---|---|---|"
echo "| one 1280x720 image, 1x | $one_1x | <= 0.3 s wall idle |"
echo "| one 1280x720 image, 2x | $one_2x | (report) |"
echo "| 100 images 1280x720, 1x (one folder, one run) | $dir_1x | <= 8 s wall idle |"
echo "| throughput of the 100-image run | $per_core | | |"
echo "| process start alone (\`lensopt --version\`) | $(best_median "$lensopt" --version) | |"
echo "| peak memory (max RSS), one image at 1x | $((peak_kb / 1024)) MiB | | <= 1024 MiB |"
echo "| peak memory (max RSS), the 100-image folder | $dir_peak_mib MiB | | <= 1024 MiB |"

if [ -f "$sample" ]; then
  echo
  echo "PSNR (dB) / SSIM of the baselines on \`sample_image.png\` (1664x896), input vs blurred"
  echo "(before relative illumination and distortion):"
  echo
  echo "| lens | 1x | 2x |"
  echo "|---|---|---|"
  for name in doublet cooke tessar; do
    row="| $name"
    for res in 1 2; do
      "$lensopt" render "lenses/$name.toml" "$sample" -o "$tmp/q_${name}_$res" -q --res-factor "$res" > /dev/null
      row="$row | $(python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); print("%.2f / %.3f" % (j["mean_psnr_db"], j["mean_ssim"]))' "$tmp/q_${name}_$res/render_metrics.json")"
    done
    echo "$row |"
  done
fi
