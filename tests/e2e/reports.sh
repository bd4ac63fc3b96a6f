#!/usr/bin/env bash
# End-to-end test of the designer's reports (issue 31): `analyze --prescription --encircled-energy
# --json` writes the chromatic focal shift, lateral colour and encircled energy without null or
# NaN, the text report prints them; the plot kinds mtf-field, chromatic and encircled-energy draw
# SVG and PNG; --max-freq and --focus-range change the mtf and through-focus axes; bad values are
# clear errors.
# Usage: reports.sh path/to/lensopt. Exit 0 pass, 1 fail.
set -u
lensopt=${1:?usage: reports.sh path/to/lensopt}
root=$(cd "$(dirname "$0")/../.." && pwd)
lens="$root/lenses/zmx/cooke_triplet_50.zmx"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
failures=0
fail() {
  echo "FAIL: $*" >&2
  failures=$((failures + 1))
}

# 1. analyze: JSON and text.
if ! "$lensopt" analyze "$lens" --prescription --encircled-energy --pupil-samples 32 --json \
  >"$tmp/a.json" 2>"$tmp/err"; then
  fail "analyze --prescription --encircled-energy --json exited non-zero: $(cat "$tmp/err")"
fi
python3 - "$tmp/a.json" <<'PY' || fail "analyze JSON: see above"
import json, math, sys
j = json.load(open(sys.argv[1]))
for key in ("prescription", "chromatic_focal_shift", "lateral_colour", "encircled_energy"):
    assert key in j, key
s = j["chromatic_focal_shift"]
assert len(s["wavelengths_nm"]) == len(s["shift_um"]) >= 2, s
assert s["max_range_um"] > 0 and s["diffraction_depth_um"] > 0, s
lc = j["lateral_colour"]
assert len(lc["lateral_colour_um"]) == len(j["fields_deg"]), lc
assert all(v is not None for v in lc["lateral_colour_um"]), lc
ee = j["encircled_energy"]
assert len(ee["fields"]) == len(j["fields_deg"]), ee
for f in ee["fields"]:
    assert f["geometric_r50_um"] is not None and f["diffraction_r50_um"] is not None, f
    assert abs(f["geometric"][-1] - 1.0) < 1e-12 or f["geometric_r90_um"] is None, f
def walk(v):
    if isinstance(v, float):
        assert math.isfinite(v)
    elif isinstance(v, dict):
        for x in v.values():
            walk(x)
    elif isinstance(v, list):
        for x in v:
            walk(x)
walk(j)
PY
"$lensopt" analyze "$lens" --prescription --encircled-energy --pupil-samples 32 >"$tmp/a.txt" \
  2>"$tmp/err" || fail "analyze text exited non-zero: $(cat "$tmp/err")"
for text in "Chromatic focal shift" "Lateral colour" "Encircled energy"; do
  grep -q "$text" "$tmp/a.txt" || fail "the text report has no '$text'"
done
grep -qi "nan" "$tmp/a.txt" && fail "the text report has a NaN"
# The flat stop the reader inserts (surface 4) has Seidel terms 0, printed as 0, never "-0".
grep -A12 "^Seidel sums" "$tmp/a.txt" | grep -qE "(^| )-0( |$)" &&
  fail "the Seidel table prints -0: $(grep -A12 '^Seidel sums' "$tmp/a.txt")"
"$lensopt" analyze "$lens" --prescription --colour-band 450,650 --json >"$tmp/b.json" \
  2>"$tmp/err" || fail "--colour-band 450,650 exited non-zero: $(cat "$tmp/err")"
python3 -c "
import json, sys
s = json.load(open('$tmp/b.json'))['chromatic_focal_shift']
assert s['band'] and len(s['wavelengths_nm']) == 11 and s['wavelengths_nm'][0] == 450.0, s
" || fail "--colour-band: not 11 samples from 450 nm"
if "$lensopt" analyze "$lens" --prescription --colour-band 650,450 >"$tmp/c.txt" 2>"$tmp/err"; then
  fail "a reversed --colour-band was accepted"
fi
grep -q "0 < lo < hi" "$tmp/err" || fail "reversed band message: $(cat "$tmp/err")"

# 2. plot: the new kinds in both formats, the axis options.
for kind in mtf-field chromatic encircled-energy; do
  for ext in svg png; do
    out="$tmp/$kind.$ext"
    "$lensopt" plot "$lens" --kind "$kind" --pupil-samples 32 --sweep-fields 5 -o "$out" \
      2>"$tmp/err" || fail "plot --kind $kind -o $kind.$ext exited non-zero: $(cat "$tmp/err")"
    [ -s "$out" ] || fail "$kind.$ext is empty or missing"
    grep -q "lensopt plot: warning" "$tmp/err" && fail "$kind.$ext: unexpected warning: $(cat "$tmp/err")"
  done
  grep -qi "nan" "$tmp/$kind.svg" && fail "$kind.svg has a NaN"
done
"$lensopt" plot "$lens" --kind mtf --pupil-samples 32 --max-freq 100 -o "$tmp/mtf.svg" \
  2>"$tmp/err" || fail "--max-freq 100 exited non-zero: $(cat "$tmp/err")"
grep -q ">100<" "$tmp/mtf.svg" || fail "--max-freq 100: no 100 tick on the frequency axis"
grep -q ">1200<\|>1000<" "$tmp/mtf.svg" && fail "--max-freq 100: the axis still runs to the cutoff"
"$lensopt" plot "$lens" --kind through-focus --pupil-samples 32 --focus-range 0.2 \
  -o "$tmp/tf.svg" 2>"$tmp/err" || fail "--focus-range 0.2 exited non-zero: $(cat "$tmp/err")"
grep -q ">200<" "$tmp/tf.svg" || fail "--focus-range 0.2: no 200 um tick"
if "$lensopt" plot "$lens" --kind mtf --max-freq -5 -o "$tmp/bad.svg" 2>"$tmp/err"; then
  fail "--max-freq -5 was accepted"
fi
[ -e "$tmp/bad.svg" ] && fail "a bad --max-freq left a file"

if [ "$failures" -gt 0 ]; then
  echo "reports.sh: $failures failure(s)" >&2
  exit 1
fi
echo "reports.sh: all checks passed"
