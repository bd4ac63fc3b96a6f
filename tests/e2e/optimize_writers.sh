#!/usr/bin/env bash
# End-to-end: `lensopt optimize` from the paper's YAML and from lenses/zmx/*.zmx writes a lens that
# analyze, convert (to .zmx and back), render and tolerance all read (a test over every writer);
# the output folder is checked before any work; a lens that is not the paper's gets bounds from
# itself, the paper's lenses keep the paper's; the result is never behind the start.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
quick=(--rings 4 --fields 3 --max-iterations 3 --glass-search none -q --json)

# The output folder is checked first (no minutes of work before the error).
if "$lensopt" optimize lenses/zmx/double_gauss_100.zmx -o "$tmp/missing/x.toml" 2> "$tmp/err.txt"; then
  fail "optimize accepted a missing output folder"
fi
grep -q "missing" "$tmp/err.txt" || fail "missing-folder message: $(cat "$tmp/err.txt")"
# No optimizer progress was printed: the error came before any work.
if grep -q "round" "$tmp/err.txt"; then fail "the output folder was checked only after the work"; fi

"$lensopt" chart -o "$tmp/chart.png" --size 96x64 > /dev/null || fail "chart"

starts=(lenses/zmx/*.zmx)
shared="${LENSOPT_SHARED_DIR:-../shared}"
if [ -f "$shared/data/reference-lenses/baseline_cooke.yml" ]; then
  starts+=("$shared/data/reference-lenses/baseline_cooke.yml")
else
  echo "note: $shared absent, the paper's YAML start is skipped"
fi

for lens in "${starts[@]}"; do
  name=$(basename "${lens%.*}")
  out="$tmp/$name.toml"
  "$lensopt" optimize "$lens" -o "$out" "${quick[@]}" > "$tmp/$name.json" ||
    fail "optimize $lens"
  python3 - "$tmp/$name.json" "$lens" <<'PY' || fail "optimize report of $lens"
import json, sys
def no_nan(x): raise ValueError("NaN in JSON")
r = json.load(open(sys.argv[1]), parse_constant=no_nan)
lens = sys.argv[2]
# Never behind the start in the documented order (every constraint met first, then the spot):
# a feasible start stays feasible; the spot may grow only when an infeasible start is made
# feasible.
start_ok, final_ok = r["start_constraints"]["all_pass"], r["final_constraints"]["all_pass"]
if start_ok:
    assert final_ok, r["final_constraints"]
if start_ok == final_ok:
    assert r["final_mean_rms_spot_um"] <= r["start_mean_rms_spot_um"] + 1e-9, r
paper = lens.endswith(".yml")
assert r["bounds"]["mode"] == ("paper" if paper else "lens"), r["bounds"]
if paper:
    assert r["bounds"]["max_glass_mm"] == 3 and r["bounds"]["min_image_clearance_mm"] == 12
PY
  # Every reader: analyze, convert (to .zmx and back to TOML), render, tolerance.
  "$lensopt" analyze "$out" --json > "$tmp/$name.analyze.json" || fail "analyze of optimized $name"
  "$lensopt" convert "$out" "$tmp/$name.zmx" > /dev/null 2>&1 || fail "convert of optimized $name"
  "$lensopt" convert "$tmp/$name.zmx" "$tmp/$name.back.toml" > /dev/null 2>&1 ||
    fail "convert back of optimized $name"
  "$lensopt" analyze "$tmp/$name.back.toml" --json > /dev/null || fail "analyze of converted $name"
  if ! "$lensopt" render "$out" "$tmp/chart.png" -o "$tmp/render-$name" -q > /dev/null \
    2> "$tmp/render.err"; then
    # F, d, C wavelengths leave the green channel empty until the system model assigns colour
    # channels for any wavelength set (issue 14, other work): the start fails the same way.
    grep -q "colour channel" "$tmp/render.err" || fail "render of optimized $name: $(cat "$tmp/render.err")"
    echo "note: render of $name waits for colour channels for any wavelength set"
  fi
  "$lensopt" tolerance "$out" --trials 20 --rings 3 --fields 3 --no-sensitivity --quiet \
    > /dev/null 2>&1 || fail "tolerance of optimized $name"
  echo "ok: $lens -> optimize -> analyze, convert, render, tolerance"
done

# --bounds paper on a lens that is not the paper's uses the paper's numbers.
"$lensopt" optimize lenses/zmx/cooke_triplet_50.zmx -o "$tmp/p.toml" "${quick[@]}" --bounds paper \
  > "$tmp/p.json" || fail "optimize --bounds paper"
python3 -c "
import json, sys
r = json.load(open('$tmp/p.json'))
assert r['bounds']['mode'] == 'paper' and r['bounds']['max_glass_mm'] == 3, r['bounds']
" || fail "--bounds paper"
echo "PASS"
