#!/usr/bin/env bash
# End-to-end: `lensopt tolerance --compensator` beyond focus (a group's decenter, the image shift
# with --spot-reference nominal): the CSV and text carry the compensator moves, the compensated
# mean spot is no worse than the uncompensated one on the same draws, and bad lists fail with a
# message that names the item.
set -euo pipefail

LENSOPT=${1:?usage: tolerance_compensators.sh path/to/lensopt}
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

common=(--trials 6 --seed 5 --rings 4 --fields 3 --jobs 2 --quiet --no-sensitivity)

"$LENSOPT" tolerance "$LENS" "${common[@]}" --csv "$TMP/plain.csv" >"$TMP/plain.txt" ||
  fail "the uncompensated run failed"
"$LENSOPT" tolerance "$LENS" "${common[@]}" --compensator "paraxial,decenter:element=2" \
  --csv "$TMP/comp.csv" >"$TMP/comp.txt" 2>"$TMP/err.txt" || fail "the run failed: $(cat "$TMP/err.txt")"
head -1 "$TMP/comp.csv" | grep -q ",comp_dx2_mm,comp_dy2_mm$" || fail "CSV header: $(head -1 "$TMP/comp.csv")"
! head -1 "$TMP/plain.csv" | grep -q "comp_" || fail "compensator columns without compensators"
grep -q "compensators beyond focus: decenter x, y of group 2" "$TMP/comp.txt" ||
  fail "the summary does not name the compensator: $(head -8 "$TMP/comp.txt")"
! grep -qi "nan" "$TMP/comp.csv" || fail "NaN in the CSV"
# Column 3 is the trial's mean spot: compensated <= uncompensated, trial by trial.
paste -d, <(cut -d, -f3 "$TMP/plain.csv" | tail -n +2) <(cut -d, -f3 "$TMP/comp.csv" | tail -n +2) |
  awk -F, '{ if ($2 > $1) { print "trial " NR-1 ": " $2 " > " $1; bad = 1 } } END { exit bad }' ||
  fail "a compensated trial is worse than uncompensated"

# The image shift with the nominal image points.
"$LENSOPT" tolerance "$LENS" "${common[@]}" --compensator image-shift --spot-reference nominal \
  --csv "$TMP/shift.csv" >"$TMP/shift.txt" || fail "the image-shift run failed"
head -1 "$TMP/shift.csv" | grep -q ",image_shift_x_mm,image_shift_y_mm$" || fail "shift CSV header"
grep -q "spot reference: the nominal image point" "$TMP/shift.txt" || fail "no spot reference line"

# Errors: the image shift about the centroids, an unknown item, a group the lens lacks.
if "$LENSOPT" tolerance "$LENS" "${common[@]}" --compensator image-shift 2>"$TMP/e1.txt" >/dev/null; then
  fail "image-shift about the centroids was accepted"
fi
grep -q "spot_reference = nominal" "$TMP/e1.txt" || fail "message: $(cat "$TMP/e1.txt")"
if "$LENSOPT" tolerance "$LENS" "${common[@]}" --compensator "best-rms,tilt:element=1" 2>"$TMP/e2.txt" >/dev/null; then
  fail "an unknown compensator was accepted"
fi
grep -q "tilt:element=1" "$TMP/e2.txt" || fail "message: $(cat "$TMP/e2.txt")"
if "$LENSOPT" tolerance "$LENS" "${common[@]}" --compensator "decenter:element=7" 2>"$TMP/e3.txt" >/dev/null; then
  fail "a missing group was accepted"
fi
grep -q "the lens has 3 groups" "$TMP/e3.txt" || fail "message: $(cat "$TMP/e3.txt")"
echo "ok"
