#!/usr/bin/env bash
# optimize on an afocal lens (issue 31, item 3; optimize/design_loss.h "Afocal merit"): the
# shipped 4x Keplerian telescope is optimized on its RMS angular spot with its angular
# magnification held (no target given) or moved to a requested one; `analyze` of each result
# gives optimize's figure and magnification; what does not apply to an afocal lens (a focal-length
# target, --focus-only, the wavefront merit) fails with a reason, never exit 0.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
zmx=tests/data/afocal/keplerian_telescope.zmx

check() {  # optimize.json analyze.json expected-magnification
  python3 - "$1" "$2" "$3" <<'PY' || fail "afocal optimize vs analyze: $1"
import json, sys
def no_nan(x): raise ValueError("NaN or Infinity in JSON: " + x)
o = json.load(open(sys.argv[1]), parse_constant=no_nan)
a = json.load(open(sys.argv[2]), parse_constant=no_nan)
m = float(sys.argv[3])
assert o["afocal"] is True and o["merit"] == "angular_spot", o.get("merit")
assert "final_mean_rms_spot_um" not in o
start, final = o["start_mean_rms_angular_spot_mrad"], o["final_mean_rms_angular_spot_mrad"]
assert final < 0.5 * start, (start, final)
assert o["constraints_met"] and o["targets_met"]
t = o["targets"][0]
assert t["quantity"] == "angular_magnification" and abs(t["final"] - m) <= 1e-6, t
assert abs(a["angular_magnification"] - m) <= 1e-6, a["angular_magnification"]
assert abs(a["mean_rms_angular_spot_mrad"] - final) <= 1e-9 * final, (a["mean_rms_angular_spot_mrad"], final)
for f, g in zip(a["fields"], o["final_rms_angular_spot_mrad"]):
    assert abs(f["rms_angular_spot_mrad"] - g) <= 1e-9 * g, (f["rms_angular_spot_mrad"], g)
print(f"{sys.argv[1]}: {start:.6f} -> {final:.6f} mrad, M = {a['angular_magnification']:.9f}")
PY
}

"$lensopt" optimize "$zmx" -o "$tmp/held.toml" --json -q > "$tmp/held.json" 2> "$tmp/held.err" \
  || fail "optimize: $(cat "$tmp/held.err")"
"$lensopt" analyze "$tmp/held.toml" --json > "$tmp/held_a.json" 2> "$tmp/held_a.err" \
  || fail "analyze of the result: $(cat "$tmp/held_a.err")"
grep -q "afocal = true" "$tmp/held.toml" || fail "the result lost afocal = true"
check "$tmp/held.json" "$tmp/held_a.json" -4

"$lensopt" optimize "$zmx" -o "$tmp/five.zmx" --json -q --target angular_magnification=-5 \
  > "$tmp/five.json" 2> "$tmp/five.err" || fail "optimize --target: $(cat "$tmp/five.err")"
"$lensopt" analyze "$tmp/five.zmx" --json > "$tmp/five_a.json" 2> "$tmp/five_a.err" \
  || fail "analyze of the .zmx result: $(cat "$tmp/five_a.err")"
check "$tmp/five.json" "$tmp/five_a.json" -5

# The text report says afocal and gives the angular spot.
"$lensopt" optimize "$zmx" -o "$tmp/t.toml" -q > "$tmp/t.txt" 2> "$tmp/t.err" || fail "optimize text"
grep -q "mean RMS angular spot (full sampling, afocal)" "$tmp/t.txt" || fail "text: $(cat "$tmp/t.txt")"
grep -q "angular_magnification = -4" "$tmp/t.txt" || fail "text lacks the held magnification"

refuse() {  # expected-message args...
  local want="$1"; shift
  if "$lensopt" optimize "$zmx" -o "$tmp/r.toml" -q "$@" > /dev/null 2> "$tmp/r.err"; then
    fail "optimize $* accepted on an afocal lens"
  fi
  grep -q "$want" "$tmp/r.err" || fail "optimize $*: $(cat "$tmp/r.err")"
}
refuse "has no focal length" --target efl_mm=100
refuse "no image distance to refocus" --focus-only
refuse "wavefront merit of an afocal lens" --merit wavefront
echo "optimize afocal e2e: ok"
