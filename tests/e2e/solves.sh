#!/usr/bin/env bash
# End-to-end tests of solves and variables in the lens file (docs/optimize.md "Variables, pickups
# and solves"): a TOML with vary flags, a curvature pickup and a focus solve is optimized with
# the report saying which variables are free and why, the pickup held and the image at the
# paraxial focus; --vary/--freeze override the file; a .zmx round trip (convert) keeps them;
# an unsupported .zmx solve is a warning naming file and line.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
quick=(--rings 6 --fields 5 --glass-search none -q --max-iterations 15)

# The Cooke triplet with flags on c1, c3, s2, a symmetric middle element (c4 = -1 x c3) and the
# last thickness a marginal-ray-height solve.
python3 - lenses/cooke.toml "$tmp/cooke.toml" <<'PY' || fail "make the lens"
import sys
text = open(sys.argv[1]).read().split("[[surfaces]]")
extra = {1: 'vary = ["radius"]\n', 2: 'vary = ["thickness"]\n', 3: 'vary = ["radius"]\n',
         4: 'pickup_curvature = { surface = 3, scale = -1 }\n',
         7: 'solve = { thickness = "marginal_height", height_mm = 0 }\n'}
out = text[0]
for i, block in enumerate(text[1:], start=1):
    out += "[[surfaces]]" + block.rstrip("\n") + "\n" + extra.get(i, "") + "\n"
open(sys.argv[2], "w").write(out)
PY
"$lensopt" optimize "$tmp/cooke.toml" -o "$tmp/out.toml" "${quick[@]}" > "$tmp/report.txt" 2> /dev/null ||
  fail "optimize with solves"
grep -q "variables free (vary flags in the lens file): c1, c3, s2" "$tmp/report.txt" ||
  fail "the report names the flagged variables: $(cat "$tmp/report.txt")"
grep -q "picked up: c4 = -1 x c3" "$tmp/report.txt" || fail "the report names the pickup"
grep -q "solved: t7 (defocus) by the marginal ray height 0 mm" "$tmp/report.txt" ||
  fail "the report names the focus solve"
grep -q 'pickup_curvature = { surface = 3, scale = -1' "$tmp/out.toml" ||
  fail "the written lens keeps its pickup"
python3 - "$tmp/out.toml" <<'PY' || fail "c4 = -c3 in the result"
import sys, re
blocks = open(sys.argv[1]).read().split("[[surfaces]]")[1:]
radius = [float(re.search(r"radius_mm = (\S+)", b).group(1)) for b in blocks]
assert radius[3] == -radius[2], radius
PY

# --freeze overrides a flag, --vary frees an unflagged value.
"$lensopt" optimize "$tmp/cooke.toml" -o "$tmp/out2.toml" "${quick[@]}" --freeze c1 --vary s3 \
  > "$tmp/report2.txt" 2> /dev/null || fail "optimize with --freeze/--vary"
grep -q "held (named in freeze: --freeze / \[optimize\] freeze): c1" "$tmp/report2.txt" ||
  fail "--freeze c1 reported"
grep -q "free (named in vary: --vary / \[optimize\] vary): s3" "$tmp/report2.txt" ||
  fail "--vary s3 reported"
if "$lensopt" optimize "$tmp/cooke.toml" -o "$tmp/out3.toml" "${quick[@]}" --vary c4 \
  2> "$tmp/err.txt" > /dev/null; then
  fail "--vary on a picked-up curvature must fail"
fi
grep -q "vary c4: it is not a variable (picked up: c4 = -1 x c3)" "$tmp/err.txt" ||
  fail "the --vary c4 error: $(cat "$tmp/err.txt")"

# A .zmx round trip keeps flags, pickups and the solve.
"$lensopt" convert "$tmp/cooke.toml" "$tmp/cooke.zmx" > /dev/null 2>&1 || fail "convert to zmx"
grep -q "MAZH 0 0" "$tmp/cooke.zmx" || fail "the .zmx has the focus solve"
"$lensopt" convert "$tmp/cooke.zmx" "$tmp/back.toml" > /dev/null 2>&1 || fail "convert back"
for key in 'vary = \["radius"\]' 'vary = \["thickness"\]' 'pickup_curvature = { surface = 3' \
  'solve = { thickness = "marginal_height"'; do
  grep -q "$key" "$tmp/back.toml" || fail "the round trip lost $key"
done

# An unsupported .zmx solve: a warning naming file and line.
sed 's/^  CURV \(.*\) 1 0 0 0 ""/  CURV \1 7 0 0 0 ""/' "$tmp/cooke.zmx" > "$tmp/odd.zmx"
grep -q " 7 0 0 0" "$tmp/odd.zmx" || fail "make the odd .zmx"
"$lensopt" analyze "$tmp/odd.zmx" > /dev/null 2> "$tmp/warn.txt" || fail "analyze odd.zmx"
grep -q "odd.zmx:[0-9]*: surface [0-9]*: curvature solve type 7 is not supported" "$tmp/warn.txt" ||
  fail "the unsupported solve warning: $(cat "$tmp/warn.txt")"
echo "solves: ok"
