#!/usr/bin/env bash
# Optimizer benchmark (issue 3): every perturbed start in lenses/starts/ optimized with the
# default options; prints a table of start -> result (full sampling), constraints and time.
# Usage: tools/bench-optimize.sh [LENSOPT] [extra optimize options...]
set -euo pipefail
cd "$(dirname "$0")/.."
lensopt="${1:-build/lensopt}"
shift || true
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
printf '| start | start spot (um) | result (um) | paper (um) | within 3%% | constraints | glasses | time (s) |\n|---|---|---|---|---|---|---|---|\n'
for start in lenses/starts/*.toml; do
  name=$(basename "$start" .toml)
  "$lensopt" optimize "$start" -o "$out/$name.toml" --json -q "$@" > "$out/$name.json" 2>/dev/null || true
  python3 - "$out/$name.json" "$name" <<'PY'
import json, sys
paper = {"doublet": 80.1, "cooke": 30.6, "tessar": 14.8}
name = sys.argv[2]
try:
    r = json.load(open(sys.argv[1]))
except Exception as e:
    print(f"| {name} | failed: {e} | | | | | | |")
    sys.exit(0)
p = paper[name.split("-")[0]]
final = r["final_mean_rms_spot_um"]
ok = final <= 1.03 * p
print(f"| {name} | {r['start_mean_rms_spot_um']:.2f} | {final:.2f} | {p} | {'yes' if ok else 'no'} | "
      f"{'all met' if r['final_constraints']['all_pass'] else 'violated'} | {', '.join(r['glasses'])} | {r['seconds']:.1f} |")
PY
done
