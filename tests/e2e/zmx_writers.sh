#!/usr/bin/env bash
# End-to-end (issue 31, items 3 and 5): negative lenses analyse (virtual image, EFL < 0);
# a lens whose glasses come from two catalogs converts .zmx -> .zmx -> .toml -> .zmx with every
# GCAT it needs, without a warning, to the same figures; `optimize -o OUT.zmx` writes a .zmx that
# analyses as the same lens written as .toml.
# Usage: zmx_writers.sh path/to/lensopt (run from the project folder).
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# 1. Negative lenses: analyze reads them (refused before: "needs a positive focal length").
for name in LC1715-A LD1464-A ACN254-100-A; do
  lens="tests/data/zmx-real/thorlabs_$name.zmx"
  "$lensopt" analyze "$lens" --json --rings 8 > "$tmp/$name.json" 2> "$tmp/$name.err" ||
    fail "analyze $lens: $(cat "$tmp/$name.err")"
  python3 - "$tmp/$name.json" <<'PY' || fail "analyze report of $name"
import json, sys
def no_nan(x): raise ValueError("NaN in JSON")
r = json.load(open(sys.argv[1]), parse_constant=no_nan)
assert r["efl_mm"] < 0 and r["f_number"] < 0, (r["efl_mm"], r["f_number"])
assert r["virtual_image"] is True and r["image_distance_mm"] < 0, r
assert r["mean_rms_spot_um"] is not None and r["mean_rms_spot_um"] > 0, r
PY
  "$lensopt" analyze "$lens" --rings 8 > "$tmp/$name.txt" 2> /dev/null || fail "analyze text $name"
  grep -q "virtual" "$tmp/$name.txt" || fail "$name: the text report does not say the image is virtual"
done

# 2. Two catalogs: N-BK7 (SCHOTT) and S-TIH6 (OHARA).
cat > "$tmp/two.zmx" <<'ZMX'
MODE SEQ
UNIT MM X W X CM MR CPMM
ENPD 10
GCAT SCHOTT OHARA
FTYP 0 0 2 3 0 0 0
XFLN 0 0
YFLN 0 5
WAVM 1 0.4861327 1
WAVM 2 0.5875618 1
WAVM 3 0.6562725 1
PWAV 2
SURF 0
  TYPE STANDARD
  CURV 0
  DISZ INFINITY
SURF 1
  STOP
  TYPE STANDARD
  CURV 0.016
  DISZ 4
  GLAS N-BK7 0 0
SURF 2
  TYPE STANDARD
  CURV -0.022
  DISZ 2.5
  GLAS S-TIH6 0 0
SURF 3
  TYPE STANDARD
  CURV -0.0078
  DISZ 97
SURF 4
  TYPE STANDARD
  CURV 0
  DISZ 0
ZMX
"$lensopt" convert "$tmp/two.zmx" "$tmp/out.zmx" > /dev/null 2> "$tmp/c1.err" || fail "convert -> .zmx"
"$lensopt" convert "$tmp/out.zmx" "$tmp/out.toml" > /dev/null 2> "$tmp/c2.err" || fail "convert -> .toml"
"$lensopt" convert "$tmp/out.toml" "$tmp/again.zmx" > /dev/null 2> "$tmp/c3.err" || fail "convert -> .zmx again"
# (The first import says the curved stop gets a flat stop surface and how the colour channels
# are assigned; nothing may be said about catalogs.)
for e in c1 c2 c3; do
  if grep -qi "catalog" "$tmp/$e.err"; then fail "convert warned ($e): $(cat "$tmp/$e.err")"; fi
done
tr -d '\r' < "$tmp/out.zmx" | grep -qx "GCAT SCHOTT OHARA" || fail "out.zmx: $(grep GCAT "$tmp/out.zmx")"
tr -d '\r' < "$tmp/again.zmx" | grep -qx "GCAT SCHOTT OHARA" || fail "again.zmx: $(grep GCAT "$tmp/again.zmx")"
grep -q 'catalog = "OHARA"' "$tmp/out.toml" || fail "out.toml does not name S-TIH6's catalog"
for lens in two.zmx out.zmx out.toml again.zmx; do
  "$lensopt" analyze "$tmp/$lens" --json --rings 8 > "$tmp/$lens.json" 2> "$tmp/$lens.err" ||
    fail "analyze $lens: $(cat "$tmp/$lens.err")"
  if grep -qi "catalog" "$tmp/$lens.err"; then fail "analyze $lens warned: $(cat "$tmp/$lens.err")"; fi
done
python3 - "$tmp"/two.zmx.json "$tmp"/out.zmx.json "$tmp"/out.toml.json "$tmp"/again.zmx.json <<'PY' ||
import json, sys
reports = [json.load(open(p)) for p in sys.argv[1:]]
keys = ("efl_mm", "bfl_mm", "epd_mm", "mean_rms_spot_um")
first = [reports[0][k] for k in keys] + reports[0]["rms_spot_um"]
for r in reports[1:]:
    other = [r[k] for k in keys] + r["rms_spot_um"]
    assert other == first, (first, other)
print("two catalogs: EFL %.9f mm, mean spot %.6f um in all four files" % (first[0], first[3]))
PY
  fail "the figures changed through the writers"

# 3. optimize -o OUT.zmx: the same lens as -o OUT.toml (the optimizer is deterministic).
quick=(--rings 4 --fields 3 --max-iterations 3 --glass-search none -q)
"$lensopt" optimize lenses/doublet.toml -o "$tmp/opt.zmx" "${quick[@]}" 2> "$tmp/o1.err" ||
  fail "optimize -o .zmx: $(cat "$tmp/o1.err")"
"$lensopt" optimize lenses/doublet.toml -o "$tmp/opt.toml" "${quick[@]}" 2> "$tmp/o2.err" ||
  fail "optimize -o .toml: $(cat "$tmp/o2.err")"
head -c 200 "$tmp/opt.zmx" | grep -q "^VERS" || fail "opt.zmx is not a .zmx"
"$lensopt" analyze "$tmp/opt.zmx" --json --rings 8 > "$tmp/opt.zmx.json" 2> /dev/null || fail "analyze opt.zmx"
"$lensopt" analyze "$tmp/opt.toml" --json --rings 8 > "$tmp/opt.toml.json" 2> /dev/null || fail "analyze opt.toml"
python3 - "$tmp/opt.zmx.json" "$tmp/opt.toml.json" <<'PY' || fail "opt.zmx and opt.toml differ"
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:])
assert a["mean_rms_spot_um"] == b["mean_rms_spot_um"], (a["mean_rms_spot_um"], b["mean_rms_spot_um"])
assert a["efl_mm"] == b["efl_mm"]
PY
if "$lensopt" optimize lenses/doublet.toml -o "$tmp/opt.yml" "${quick[@]}" 2> "$tmp/o3.err"; then
  fail "optimize accepted -o .yml"
fi
grep -q ".toml or Zemax .zmx" "$tmp/o3.err" || fail "-o .yml message: $(cat "$tmp/o3.err")"
echo "zmx writers: ok"
