#!/usr/bin/env bash
# Tolerancing benchmark (issue 5): 10,000 Monte-Carlo trials on the Tessar at the default
# tolerancing sampling (16 rings x 11 fields x 15 wavelengths, ray aiming on; target <= 60 s on
# 2 cores), and the time per trial at the paper's full sampling (32 rings x 21 fields).
# Usage: tools/bench-tolerance.sh path/to/lensopt [trials] [full-sampling trials]
# Prints wall and CPU times (the machine may be shared: CPU seconds per trial are the steadier
# figure), the Tessar's summary and the top of its sensitivity table.
set -euo pipefail

LENSOPT=${1:?usage: bench-tolerance.sh path/to/lensopt [trials] [full-sampling trials]}
TRIALS=${2:-10000}
FULL_TRIALS=${3:-200}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
LENS="$ROOT/lenses/tessar.toml"
MAX_SPOT_UM=16.5
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

# Runs lensopt with the given arguments, JSON to $TMP/$1.json; prints "wall_s cpu_s" (CPU: user
# + system of the run, from bash's `time`).
timed() {
  local name=$1
  shift
  local TIMEFORMAT='%R %U %S'
  { time "$LENSOPT" tolerance "$LENS" --quiet --json "$@" >"$TMP/$name.json" 2>"$TMP/$name.err"; } \
    2>"$TMP/$name.time" || { cat "$TMP/$name.err" >&2; exit 1; }
  tail -1 "$TMP/$name.time" | awk '{print $1, $2 + $3}'
}

cpu_model=$(grep -m1 "model name" /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
echo "machine: nproc $(nproc), CPU ${cpu_model:-unknown}, load average $(cut -d' ' -f1-3 /proc/loadavg)"

read -r wall_default cpu_default < <(timed default --trials "$TRIALS" --jobs 2 --seed 1 \
  --max-spot-um "$MAX_SPOT_UM")
read -r wall_full1 cpu_full1 < <(timed full1 --trials "$FULL_TRIALS" --jobs 1 --rings 32 \
  --fields 21 --no-sensitivity)
read -r wall_full2 cpu_full2 < <(timed full2 --trials "$FULL_TRIALS" --jobs 2 --rings 32 \
  --fields 21 --no-sensitivity)

printf '\n%s trials, default sampling (16 rings x 11 fields), --jobs 2:\n' "$TRIALS"
printf '  wall %.1f s (%.2f ms per trial), CPU %.1f s (%.2f ms CPU per trial)\n' \
  "$wall_default" "$(echo "1000 * $wall_default / $TRIALS" | bc -l)" "$cpu_default" \
  "$(echo "1000 * $cpu_default / $TRIALS" | bc -l)"
printf '%s trials, full sampling (32 rings x 21 fields):\n' "$FULL_TRIALS"
printf '  --jobs 1: wall %.2f ms per trial, CPU %.2f ms per trial\n' \
  "$(echo "1000 * $wall_full1 / $FULL_TRIALS" | bc -l)" \
  "$(echo "1000 * $cpu_full1 / $FULL_TRIALS" | bc -l)"
printf '  --jobs 2: wall %.2f ms per trial, CPU %.2f ms per trial\n' \
  "$(echo "1000 * $wall_full2 / $FULL_TRIALS" | bc -l)" \
  "$(echo "1000 * $cpu_full2 / $FULL_TRIALS" | bc -l)"
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"

if command -v python3 >/dev/null 2>&1; then
  python3 - "$TMP/default.json" "$TMP/full1.json" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
f = json.load(open(sys.argv[2]))
s = d["summary"]
print(f"\nTessar, {d['trials']} trials, seed {d['seed']}, {d['distribution']}, compensator "
      f"{d['compensator']}, default sampling:")
print(f"  mean RMS spot (um): nominal {s['nominal_um']:.3f}, mean {s['mean_um']:.3f}, "
      f"std {s['std_um']:.3f}, p50 {s['p50_um']:.3f}, p90 {s['p90_um']:.3f}, "
      f"p95 {s['p95_um']:.3f}, p99 {s['p99_um']:.3f}, worst {s['worst_um']:.3f}")
print(f"  yield (mean spot <= {s['max_spot_um']:g} um): {100 * s['yield']:.2f} %")
e = s["efl_mm"]
print(f"  EFL (mm): nominal {e['nominal']:.4f}, std {e['std']:.4f}; trials with ray failures: "
      f"{s['trials_with_ray_failures']}")
fs = f["summary"]
print(f"  full sampling, {f['trials']} trials: nominal {fs['nominal_um']:.3f}, "
      f"mean {fs['mean_um']:.3f}, std {fs['std_um']:.3f}, p90 {fs['p90_um']:.3f}")
print("  sensitivity (each tolerance alone at +-limit, change in mean spot, um):")
for row in d["sensitivity"][:8]:
    print(f"    {row['rank']:2d}. {row['parameter']:<5} +-{row['tolerance']:<8} "
          f"{row['delta_spot_plus_um']:+.3f} / {row['delta_spot_minus_um']:+.3f}  "
          f"{row['description']}")
EOF
fi
