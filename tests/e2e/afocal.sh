#!/usr/bin/env bash
# End-to-end tests of afocal lenses (issue 31, item 3; analysis/afocal.h): a .zmx telescope with
# OpticStudio's Afocal Image Space flag is analysed in angle (text and JSON: angular
# magnification and exit pupil against the closed forms, no NaN), plotted as a spot in angle,
# converted to TOML and back with the flag, and refused by tolerance (an image-plane command) with
# a reason.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
zmx=tests/data/afocal/keplerian_telescope.zmx

"$lensopt" analyze "$zmx" --json --rings 8 --pupil-samples 32 > "$tmp/a.json" 2> "$tmp/a.err" \
  || fail "analyze --json: $(cat "$tmp/a.err")"
python3 - "$tmp/a.json" <<'PY' || fail "afocal JSON"
import json, sys
def no_nan(x): raise ValueError("NaN or Infinity in JSON: " + x)
r = json.load(open(sys.argv[1]), parse_constant=no_nan)
assert r["afocal"] is True
assert abs(r["angular_magnification"] + 4.0) < 1e-9, r["angular_magnification"]
assert abs(r["exit_pupil_z_mm"] - 31.25) < 1e-7, r["exit_pupil_z_mm"]
assert abs(r["exit_pupil_diameter_mm"] - 5.0) < 1e-8, r["exit_pupil_diameter_mm"]
assert "efl_mm" not in r and "f_number" not in r
assert len(r["fields"]) == 3
for f in r["fields"]:
    for key in ["output_chief_angle_deg", "angular_distortion_percent", "rms_angular_spot_mrad",
                "rms_angular_spot_arcmin", "rms_wavefront_waves", "strehl"]:
        assert f[key] is not None, key
assert r["fields"][2]["output_chief_angle_deg"] < -3.9
assert r["mean_rms_angular_spot_mrad"] > 0
PY
"$lensopt" analyze "$zmx" --zernike 9 > "$tmp/a.txt" || fail "analyze text"
grep -q "angular magnification" "$tmp/a.txt" || fail "text lacks the angular magnification"
grep -q "Zernike" "$tmp/a.txt" || fail "text lacks the Zernike fit"
if "$lensopt" analyze "$zmx" --prescription 2> "$tmp/p.err" > /dev/null; then
  fail "--prescription accepted on an afocal lens"
fi
grep -q "does not apply to an afocal lens" "$tmp/p.err" || fail "prescription refusal: $(cat "$tmp/p.err")"

# The spot diagram in angle.
"$lensopt" plot "$zmx" --kind spot -o "$tmp/spot.svg" > /dev/null 2> "$tmp/spot.err" || fail "plot spot"
# The summary line names the boxes' unit: microradians, not micrometres.
grep -q "spot boxes .* urad" "$tmp/spot.err" || fail "plot summary does not give the spot boxes in urad: $(cat "$tmp/spot.err")"
grep -q "rad" "$tmp/spot.svg" || fail "spot plot not in angle units"
if "$lensopt" plot "$zmx" --kind layout -o "$tmp/layout.svg" 2> "$tmp/l.err"; then
  fail "plot --kind layout accepted on an afocal lens"
fi
grep -q "afocal" "$tmp/l.err" || fail "layout refusal: $(cat "$tmp/l.err")"

# TOML and back: the flag is kept.
"$lensopt" convert "$zmx" "$tmp/k.toml" > /dev/null 2>&1 || fail "convert to TOML"
grep -q "afocal = true" "$tmp/k.toml" || fail "TOML lacks afocal = true"
"$lensopt" convert "$tmp/k.toml" "$tmp/k.zmx" > /dev/null 2>&1 || fail "convert to zmx"
grep -q "^FTYP 0 0 3 3 0 0 1" "$tmp/k.zmx" || fail "zmx lacks the afocal flag: $(grep FTYP "$tmp/k.zmx")"

# The image-plane commands refuse it with the reason (never exit 0); optimize measures it in
# angle (tests/e2e/optimize_afocal.sh).
for cmd in tolerance; do
  if "$lensopt" $cmd "$zmx" > /dev/null 2> "$tmp/$cmd.err"; then
    fail "$cmd accepted an afocal lens"
  fi
  grep -q "afocal" "$tmp/$cmd.err" || fail "$cmd refusal: $(cat "$tmp/$cmd.err")"
done
echo "afocal e2e: ok"
