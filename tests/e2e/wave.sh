#!/usr/bin/env bash
# End-to-end tests of the wave optics (issue 17): `analyze --wave` text and JSON (no NaN, MTF at
# the asked frequencies, values in range), Zernike fits, the wave-optics plot kinds and the
# report's MTF, `bench --wave`, `optimize --merit wavefront`, `export --diffraction` and
# `render --psf diffraction|auto` (the default geometric output unchanged).
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

"$lensopt" analyze lenses/cooke.toml --wave --fields 3 --rings 8 --pupil-samples 32 \
  --mtf-freqs 10,30,50 --json > "$tmp/cooke.json"
python3 - "$tmp/cooke.json" <<'PY' || fail "analyze --wave --json"
import json, sys
def no_nan(x): raise ValueError("NaN or Infinity in JSON: " + x)
r = json.load(open(sys.argv[1]), parse_constant=no_nan)
w = r["wave"]
assert w["frequencies_cyc_mm"] == [10, 30, 50], w["frequencies_cyc_mm"]
assert w["pupil_samples"] == 32 and w["fft_n"] >= 64
assert len(w["fields"]) == 3
for f in w["fields"]:
    assert f["rms_wavefront_waves"] > 0
    assert 0 < f["strehl"] <= 1
    for key in ["mtf_tangential", "mtf_sagittal", "geometric_mtf_tangential", "geometric_mtf_sagittal"]:
        assert len(f[key]) == 3 and all(0 <= v <= 1 + 1e-9 for v in f[key]), (key, f[key])
    # MTF falls with frequency for this lens.
    assert f["mtf_tangential"][0] >= f["mtf_tangential"][2] - 1e-9
PY

"$lensopt" analyze lenses/cooke.toml --wave --fields 3 --rings 8 --pupil-samples 32 > "$tmp/cooke.txt"
grep -q "RMS WFE" "$tmp/cooke.txt" || fail "text lacks the wave table"
grep -q "Strehl" "$tmp/cooke.txt" || fail "text lacks the Strehl ratio"

for kind in mtf through-focus wavefront psf-diffraction; do
  "$lensopt" plot lenses/cooke.toml --kind "$kind" --pupil-samples 32 \
    -o "$tmp/$kind.svg" 2> /dev/null || fail "plot --kind $kind"
  grep -q "<svg" "$tmp/$kind.svg" || fail "plot $kind is not SVG"
done

"$lensopt" bench --wave --pupil-samples 32 --repeats 1 --json > "$tmp/bench.json"
python3 -c "import json,sys; r=json.load(open(sys.argv[1])); assert r['fields']==21 and r['wavelengths']==3 and r['diffraction_mtf_ms']>0" "$tmp/bench.json" \
  || fail "bench --wave"
# Zernike fits in the JSON and the text.
"$lensopt" analyze lenses/cooke.toml --fields 2 --rings 4 --pupil-samples 32 --zernike 9 \
  --zernike-order standard --json > "$tmp/zernike.json"
python3 - "$tmp/zernike.json" <<'PY' || fail "analyze --zernike --json"
import json, sys
def no_nan(x): raise ValueError("NaN or Infinity in JSON: " + x)
w = json.load(open(sys.argv[1]), parse_constant=no_nan)["wave"]
assert w["zernike_terms"] == 9 and w["zernike_ordering"] == "standard"
for f in w["fields"]:
    for m in f["per_wavelength"]:
        assert len(m["zernike_waves"]) == 9, m
        assert m["zernike_residual_rms_waves"] >= 0
PY
"$lensopt" analyze lenses/cooke.toml --fields 2 --rings 4 --pupil-samples 32 --zernike 5 \
  > "$tmp/zernike.txt" || fail "analyze --zernike"
grep -q "Zernike fringe coefficients" "$tmp/zernike.txt" || fail "analyze --zernike text"

# The report page carries the MTF chart.
"$lensopt" plot lenses/cooke.toml --kind report --pupil-samples 16 -o "$tmp/report.svg" 2> /dev/null \
  || fail "plot --kind report"
grep -q "diffraction MTF" "$tmp/report.svg" || fail "the report lacks the MTF chart"

# optimize --merit wavefront lowers the RMS wavefront (a short run).
"$lensopt" optimize lenses/zmx/achromat_ac254_100.zmx -o "$tmp/achromat.toml" --merit wavefront \
  --fields 3 --rings 4 --max-iterations 5 --wavefront-pupil-samples 8 --json -q > "$tmp/opt.json" \
  || fail "optimize --merit wavefront"
python3 - "$tmp/opt.json" <<'PY' || fail "optimize --merit wavefront JSON"
import json, sys
r = json.load(open(sys.argv[1]))
assert r["merit"] == "wavefront"
assert 0 < r["final_mean_rms_wavefront_waves"] < r["start_mean_rms_wavefront_waves"], r
PY

# The wavefront merit's design meets its constraints at full sampling. The Cooke's largest ray
# angle is reached by an interior pupil ray at a field between the optimization's merit fields:
# before the feasibility step at every constraint field, this run ended at 60.54 deg (> 60).
"$lensopt" optimize lenses/cooke.toml -o "$tmp/cooke_wave.toml" --merit wavefront --max-iterations 10 \
  --json -q > "$tmp/cooke_wave.json" || fail "optimize cooke --merit wavefront"
python3 - "$tmp/cooke_wave.json" <<'PY' || fail "optimize cooke --merit wavefront: constraints"
import json, sys
r = json.load(open(sys.argv[1]))
rows = {row["name"]: row for row in r["final_constraints"]["rows"]}
angle = rows["largest ray angle (deg)"]
assert r["constraints_met"] and angle["pass"] and angle["value"] <= 60.0, angle
assert r["final_mean_rms_wavefront_waves"] < r["start_mean_rms_wavefront_waves"], r
PY

# export --diffraction writes the diffraction PSFs beside the geometric ones.
"$lensopt" export lenses/tessar.toml -o "$tmp/export" --image-size 96x64 --diffraction \
  --pupil-samples 32 > /dev/null 2> "$tmp/export.err" || fail "export --diffraction"
for f in psf/field_00.exr psf/field_00_diffraction.exr psf_sheet.png psf_sheet_diffraction.png; do
  [ -f "$tmp/export/$f" ] || fail "export --diffraction: missing $f"
done
python3 - "$tmp/export/fields.json" <<'PY' || fail "export --diffraction fields.json"
import json, sys
r = json.load(open(sys.argv[1]))
for f in r["fields"]:
    assert f["psf_diffraction"].endswith("_diffraction.exr")
    assert 0 < f["strehl"] <= 1 and all(0 < e <= 1 + 1e-9 for e in f["diffraction_energy_share_rgb"])
PY

# render: the default equals --psf geometric byte for byte; diffraction and auto render and differ.
mkdir -p "$tmp/in"
"$lensopt" chart -o "$tmp/in/chart.png" --size 96x64 > /dev/null
for psf in default geometric diffraction auto; do
  opt=(); [ "$psf" = default ] || opt=(--psf "$psf" --pupil-samples 32)
  "$lensopt" render lenses/tessar.toml "$tmp/in/chart.png" -o "$tmp/render-$psf" -q "${opt[@]}" \
    > /dev/null 2> "$tmp/render-$psf.err" || fail "render --psf $psf: $(cat "$tmp/render-$psf.err")"
done
cmp -s "$tmp/render-default/chart.png" "$tmp/render-geometric/chart.png" \
  || fail "render --psf geometric differs from the default"
cmp -s "$tmp/render-default/chart.png" "$tmp/render-diffraction/chart.png" \
  && fail "render --psf diffraction equals the geometric image"
grep -q "diffraction PSFs" "$tmp/render-auto.err" || fail "render --psf auto: no summary"
echo "wave e2e: ok"
