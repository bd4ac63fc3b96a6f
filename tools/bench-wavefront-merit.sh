#!/usr/bin/env bash
# Wavefront-merit benchmark (issue 17): `lensopt optimize` of a lens (default the Cooke) with the
# spot merit and with `--merit wavefront`, each timed (wall clock of the whole command and the
# optimizer's own seconds), then both results analysed alike (`analyze --wave`: mean RMS
# wavefront, mean Strehl; mean RMS spot). Prints a Markdown table; CPU (s) is the optimize
# process's user + system time (steadier than the wall clock on a shared machine).
# Usage: tools/bench-wavefront-merit.sh [LENSOPT] [LENS] [extra optimize options...]
set -euo pipefail
cd "$(dirname "$0")/.."
lensopt="${1:-build/lensopt}"
lens="${2:-lenses/cooke.toml}"
shift $(( $# >= 2 ? 2 : $# )) || true
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "machine: $(nproc) cores; $(uptime | sed 's/.*load/load/')"
printf '| merit | wall (s) | CPU (s) | optimizer (s) | LM iterations | evaluations (Jacobians) | mean RMS wavefront (waves) | mean Strehl | mean RMS spot (um) |\n|---|---|---|---|---|---|---|---|---|\n'
TIMEFORMAT='%U %S'
for merit in spot wavefront; do
  start=$(date +%s.%N)
  { time "$lensopt" optimize "$lens" -o "$out/$merit.toml" --json -q --merit "$merit" "$@" \
      > "$out/$merit.json" 2> "$out/$merit.err"; } 2> "$out/$merit.time"
  end=$(date +%s.%N)
  cat "$out/$merit.err" >&2
  "$lensopt" analyze "$out/$merit.toml" --wave --pupil-samples 64 --json > "$out/$merit.analysis.json"
  python3 - "$out/$merit.json" "$out/$merit.analysis.json" "$merit" "$start" "$end" \
    "$out/$merit.time" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
a = json.load(open(sys.argv[2]))
wall = float(sys.argv[5]) - float(sys.argv[4])
cpu = sum(float(v) for v in open(sys.argv[6]).read().split()[-2:])
print(f"| {sys.argv[3]} | {wall:.1f} | {cpu:.1f} | {r['seconds']:.1f} | {r['iterations']} | "
      f"{r['loss_evaluations']} ({r['jacobian_evaluations']}) | "
      f"{a['wave']['mean_rms_wavefront_waves']:.4f} | {a['wave']['mean_strehl']:.4f} | "
      f"{a['mean_rms_spot_um']:.3f} |")
PY
done
"$lensopt" analyze "$lens" --wave --pupil-samples 64 --json > "$out/start.analysis.json"
python3 - "$out/start.analysis.json" <<'PY'
import json, sys
a = json.load(open(sys.argv[1]))
print(f"start: mean RMS wavefront {a['wave']['mean_rms_wavefront_waves']:.4f} waves, "
      f"mean Strehl {a['wave']['mean_strehl']:.4f}, mean RMS spot {a['mean_rms_spot_um']:.3f} um")
PY
