#!/usr/bin/env bash
# End-to-end test of optimize on a diverging lens (issue 31, item 3; optimize/virtual_image.h):
# the Thorlabs LD1464-A bi-concave lens (EFL -49.8 mm) with off-axis fields is optimized for
# minimum spot at --target efl_mm=-50; the EFL is met to 1e-6, the RMS spot at the virtual image
# does not increase, the virtual image's bounds are reported and met, and analyze of the written
# lens gives optimize's EFL and spots (the same numbers by two paths).
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

"$lensopt" convert tests/data/zmx-real/thorlabs_LD1464-A.zmx "$tmp/ld.toml" > /dev/null 2>&1 ||
  fail "convert LD1464-A"
grep -q '^fields = \[0.0\]$' "$tmp/ld.toml" || fail "converted TOML has no on-axis field line"
sed -i 's/^fields = \[0.0\]$/fields = [0.0, 2.0, 4.0]/' "$tmp/ld.toml"
"$lensopt" optimize "$tmp/ld.toml" -o "$tmp/out.toml" --target efl_mm=-50 --json --rings 6 \
  --fields 3 --glass-search none --max-iterations 15 -q > "$tmp/o.json" ||
  fail "optimize a diverging lens"
"$lensopt" analyze "$tmp/out.toml" --json > "$tmp/a.json" || fail "analyze the result"
python3 - "$tmp/o.json" "$tmp/a.json" <<'PY' || fail "diverging optimize figures"
import json, sys
def no_nan(x): raise ValueError("NaN in JSON")
o = json.load(open(sys.argv[1]), parse_constant=no_nan)
a = json.load(open(sys.argv[2]), parse_constant=no_nan)
rows = {t["quantity"]: t for t in o["targets"]}
assert abs(rows["efl_mm"]["final"] + 50) <= 1e-6, rows["efl_mm"]
assert rows["efl_mm"]["pass"], rows["efl_mm"]
assert o["final_mean_rms_spot_um"] <= o["start_mean_rms_spot_um"], o
assert o["final_constraints"]["all_pass"] is True, o["final_constraints"]
b = o["bounds"]
assert 0 < b["min_virtual_image_mm"] < b["max_virtual_image_mm"], b
assert any("virtual" in line for line in o["log"]), o["log"]
# analyze of the written lens: the same EFL and spots, a virtual image.
assert abs(a["efl_mm"] + 50) <= 1e-6, a["efl_mm"]
assert a["virtual_image"] is True
assert a["image_distance_mm"] < 0, a["image_distance_mm"]
assert abs(a["mean_rms_spot_um"] - o["final_mean_rms_spot_um"]) <= 1e-9 * a["mean_rms_spot_um"]
for x, y in zip(a["rms_spot_um"], o["final_rms_spot_um"]):
    assert abs(x - y) <= 1e-9 * max(x, 1e-3), (a["rms_spot_um"], o["final_rms_spot_um"])
print("LD1464-A at efl_mm=-50: spot", o["start_mean_rms_spot_um"], "->",
      o["final_mean_rms_spot_um"], "um; virtual image", -a["image_distance_mm"],
      "mm before the last surface; bounds", b["min_virtual_image_mm"], b["max_virtual_image_mm"])
PY
# The virtual image's bounds from the command line (they were [optimize] keys only): the run's
# bounds are the ones given; on a converging lens they are refused with the reason.
"$lensopt" optimize "$tmp/ld.toml" -o "$tmp/vb.toml" --target efl_mm=-50 --json --rings 6 \
  --fields 3 --glass-search none --max-iterations 5 -q --min-virtual-image-mm 30 \
  --max-virtual-image-mm 80 > "$tmp/vb.json" || fail "optimize --min/--max-virtual-image-mm"
python3 - "$tmp/vb.json" <<'PY' || fail "virtual-image bounds from the command line"
import json, sys
b = json.load(open(sys.argv[1]))["bounds"]
assert (b["min_virtual_image_mm"], b["max_virtual_image_mm"]) == (30, 80), b
PY
if "$lensopt" optimize lenses/doublet.toml -o "$tmp/d.toml" -q --max-virtual-image-mm 80 \
  > /dev/null 2> "$tmp/d.err"; then
  fail "--max-virtual-image-mm accepted on a converging lens"
fi
grep -q "real image" "$tmp/d.err" || fail "converging refusal: $(cat "$tmp/d.err")"
echo "optimize_diverging: ok"
