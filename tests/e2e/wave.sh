#!/usr/bin/env bash
# End-to-end tests of the wave optics (issue 17): `analyze --wave` text and JSON (no NaN, MTF at
# the asked frequencies, values in range), the wave-optics plot kinds, `bench --wave`.
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
echo "wave e2e: ok"
