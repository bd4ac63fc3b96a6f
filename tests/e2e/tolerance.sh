#!/usr/bin/env bash
# End-to-end: `lensopt tolerance` on the Tessar at a small sampling: CSV, JSON and SVG outputs,
# the same per-trial CSV with --jobs 1 and --jobs 2, the text summary, and bad tolerances
# (command line and [tolerance] table) failing with a message that names them.
set -euo pipefail

LENSOPT=${1:?usage: tolerance.sh path/to/lensopt}
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
LENS="$ROOT/lenses/tessar.toml"
if [ ! -f "$LENS" ]; then
  echo "skipped: $LENS is missing"
  exit 77
fi
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

fail() {
  echo "FAIL: $*" >&2
  exit 1
}

common=(--trials 50 --seed 7 --rings 8 --fields 5)

# 1. A small run with every output.
"$LENSOPT" tolerance "$LENS" "${common[@]}" --jobs 1 --csv "$TMP/jobs1.csv" \
  --histogram "$TMP/hist.svg" --max-spot-um 17 --json >"$TMP/run.json" 2>"$TMP/progress.txt" ||
  fail "the run failed: $(cat "$TMP/progress.txt")"
grep -q "50/50 trials" "$TMP/progress.txt" || fail "no progress on stderr"
[ "$(wc -l <"$TMP/jobs1.csv")" -eq 51 ] || fail "CSV should have a header and 50 rows"
head -1 "$TMP/jobs1.csv" | grep -q "^trial,valid,mean_spot_um,efl_mm" || fail "CSV header"
grep -q "<svg" "$TMP/hist.svg" || fail "histogram is not an SVG"
grep -q "</svg>" "$TMP/hist.svg" || fail "histogram SVG is incomplete"
! grep -qi "nan" "$TMP/jobs1.csv" || fail "NaN in the CSV"
! grep -q "NaN" "$TMP/run.json" || fail "NaN in the JSON"
if command -v python3 >/dev/null 2>&1; then
  python3 - "$TMP/run.json" <<'EOF' || fail "JSON content"
import json, sys
j = json.load(open(sys.argv[1]))
s = j["summary"]
assert j["trials"] == 50 and len(j["trial_results"]) == 50
assert j["compensator"] == "paraxial" and j["distribution"] == "uniform"
for k in ("nominal_um", "mean_um", "std_um", "p50_um", "p90_um", "p95_um", "p99_um", "worst_um"):
    assert isinstance(s[k], float) and s[k] > 0, k
assert s["p50_um"] <= s["p90_um"] <= s["p95_um"] <= s["p99_um"] <= s["worst_um"]
assert 0.0 <= s["yield"] <= 1.0
sens = j["sensitivity"]
# 7 curvatures, 4 thicknesses, 4 nd, 4 vd + 3 groups x (tedx, tedy, tetx, tety) + the 7 surfaces'
# wedges (tstx, tsty; on by default, docs/tolerance.md)
assert len(sens) == 45
assert all(sens[i]["score_um"] >= sens[i + 1]["score_um"] for i in range(len(sens) - 1))
EOF
else
  grep -q '"p99_um"' "$TMP/run.json" || fail "JSON summary"
  grep -q '"sensitivity"' "$TMP/run.json" || fail "JSON sensitivity"
fi

# 2. The same seed gives the same per-trial CSV with two threads; the text summary.
"$LENSOPT" tolerance "$LENS" "${common[@]}" --jobs 2 --csv "$TMP/jobs2.csv" --quiet \
  >"$TMP/summary.txt"
cmp -s "$TMP/jobs1.csv" "$TMP/jobs2.csv" || fail "per-trial CSV differs between --jobs 1 and 2"
for word in nominal p90 p99 worst Sensitivity; do
  grep -q "$word" "$TMP/summary.txt" || fail "summary lacks '$word'"
done
# Only the requested files were written (atomic writes leave no temporaries).
[ "$(ls "$TMP" | grep -cv -e '^jobs1.csv$' -e '^jobs2.csv$' -e '^hist.svg$' -e '^run.json$' \
  -e '^progress.txt$' -e '^summary.txt$')" -eq 0 ] || fail "stray files: $(ls "$TMP")"

# 3. Bad tolerances fail and name the culprit.
if "$LENSOPT" tolerance "$LENS" --trials 5 --quiet --glass-thickness-mm=-0.05 \
  >/dev/null 2>"$TMP/err.txt"; then
  fail "a negative tolerance was accepted"
fi
grep -q -- "--glass-thickness-mm" "$TMP/err.txt" || fail "message does not name the tolerance: $(cat "$TMP/err.txt")"

cp "$LENS" "$TMP/tol.toml"
printf '\n[tolerance]\nnd = 5e-4\nvd_pct = -0.5\n' >>"$TMP/tol.toml"
line=$(grep -n "^vd_pct" "$TMP/tol.toml" | cut -d: -f1)
if "$LENSOPT" tolerance "$TMP/tol.toml" --trials 5 --quiet >/dev/null 2>"$TMP/err.txt"; then
  fail "a negative [tolerance] entry was accepted"
fi
grep -q "tol.toml:$line:.*vd_pct" "$TMP/err.txt" || fail "no file:line naming vd_pct: $(cat "$TMP/err.txt")"

cp "$LENS" "$TMP/unknown.toml"
printf '\n[tolerance]\ntilt_deg = 0.1\n' >>"$TMP/unknown.toml"
if "$LENSOPT" tolerance "$TMP/unknown.toml" --trials 5 --quiet >/dev/null 2>"$TMP/err.txt"; then
  fail "an unknown [tolerance] key was accepted"
fi
grep -q "tilt_deg" "$TMP/err.txt" || fail "message does not name the unknown key: $(cat "$TMP/err.txt")"

# The command line wins over the table: a valid table value overridden on the command line.
cp "$LENS" "$TMP/table.toml"
printf '\n[tolerance]\nnd = 1e-3\ntrials = 7\n' >>"$TMP/table.toml"
"$LENSOPT" tolerance "$TMP/table.toml" --rings 4 --fields 3 --nd 0 --quiet --json \
  --no-sensitivity >"$TMP/table.json"
grep -q '"nd": 0.0' "$TMP/table.json" || fail "--nd did not override the table"
grep -q '"trials": 7' "$TMP/table.json" || fail "trials from the table not used"

# 3. A lens traced as written (a vendor's .zmx, one field on axis) is not scaled: the report says
# so, and its JSON has no null (no spec focal length d / (2 tan 0) = inf, no yield without a
# limit); every trial of this lens is valid.
"$LENSOPT" tolerance tests/data/zmx-real/thorlabs_AC254-100-A.zmx --trials 5 --rings 4 --quiet \
  2>/dev/null >"$TMP/written.txt" || fail "tolerance of a .zmx"
grep -q "traced as written (not scaled)" "$TMP/written.txt" || fail "as-written: $(head -3 "$TMP/written.txt")"
! grep -q "inf mm" "$TMP/written.txt" || fail "an infinite focal length in the text"
if command -v python3 >/dev/null 2>&1; then
  "$LENSOPT" tolerance tests/data/zmx-real/thorlabs_AC254-100-A.zmx --trials 5 --rings 4 --quiet \
    --json 2>/dev/null >"$TMP/written.json" || fail "tolerance --json of a .zmx"
  python3 - "$TMP/written.json" <<'EOF' || fail "null or non-finite values in the JSON of a .zmx"
import json, math, sys
def bad(j, path="$"):
    if j is None or (isinstance(j, float) and not math.isfinite(j)):
        return [path]
    if isinstance(j, dict):
        return [p for k, v in j.items() for p in bad(v, path + "." + k)]
    if isinstance(j, list):
        return [p for i, v in enumerate(j) for p in bad(v, f"{path}[{i}]")]
    return []
j = json.load(open(sys.argv[1]), parse_constant=lambda c: None)
assert j["scaled_to_spec"] is False and "spec_focal_length_mm" not in j, j.get("spec_focal_length_mm")
assert not bad(j), bad(j)[:5]
EOF
fi

echo "tolerance e2e: ok"
