#!/usr/bin/env bash
# End-to-end tests of `lensopt chart`, `lensopt render` and `lensopt export`: a generated chart
# folder with a corrupt file renders to the same tree (formats and bit depths kept), the metrics
# CSV/JSON list every image, the run ends non-zero naming the bad file, a second run resumes
# (skips what exists), --force renders again; bad output folders and options are refused; the
# export writes its maps. The part on ../shared's sample photo exits 77 (skipped) without it.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# A small dataset tree: charts as PNG (8-bit), 16-bit TIFF and EXR, one corrupt JPEG, one text file.
mkdir -p "$tmp/in/a/b"
"$lensopt" chart -o "$tmp/in/chart.png" --size 240x160 > /dev/null || fail "chart png"
"$lensopt" chart -o "$tmp/in/a/chart16.tif" --size 200x120 > /dev/null || fail "chart tif"
"$lensopt" chart -o "$tmp/in/a/b/chart.exr" --size 160x96 --no-text > /dev/null || fail "chart exr"
printf 'not a jpeg' > "$tmp/in/a/broken.jpg"
printf 'notes' > "$tmp/in/a/readme.txt"
python3 - "$tmp/in/chart.png" <<'PY' || fail "chart content"
import struct, sys, zlib
data = open(sys.argv[1], "rb").read()
assert data[:8] == b"\x89PNG\r\n\x1a\n"
w, h, depth, colour = struct.unpack(">IIBB", data[16:26])
assert (w, h, depth, colour) == (240, 160, 8, 2), (w, h, depth, colour)
PY

# Render: non-zero exit naming the corrupt file, the rest written.
if "$lensopt" render lenses/cooke.toml "$tmp/in" -o "$tmp/out" --jobs 2 > "$tmp/stdout" 2> "$tmp/stderr"; then
  fail "render succeeded despite a corrupt input"
fi
grep -q "broken.jpg" "$tmp/stderr" || fail "the corrupt file is not named: $(cat "$tmp/stderr")"
grep -q "could not be rendered" "$tmp/stderr" || fail "no failure summary"
for f in chart.png a/chart16.tif a/b/chart.exr render_metrics.csv render_metrics.json; do
  [ -f "$tmp/out/$f" ] || fail "missing output $f"
done
[ ! -e "$tmp/out/a/broken.jpg" ] || fail "an output was written for the corrupt input"
[ ! -e "$tmp/out/a/readme.txt" ] || fail "a non-image was copied"
[ -z "$(find "$tmp/out" -name '.*')" ] || fail "temporary files left: $(find "$tmp/out" -name '.*')"
grep -q "rendered 3, skipped 0 (already there), failed 1" "$tmp/stdout" || fail "summary: $(cat "$tmp/stdout")"
# Same sizes, formats and bit depths.
python3 - "$tmp" <<'PY' || fail "formats"
import subprocess, sys
tmp = sys.argv[1]
def info(p):
    return subprocess.run(["oiiotool", "--info", p], capture_output=True, text=True).stdout
for rel, size, kind in [("chart.png", "240 x  160", "uint8 png"),
                        ("a/chart16.tif", "200 x  120", "uint16 tiff"),
                        ("a/b/chart.exr", "160 x   96", "half openexr")]:
    i, o = info(f"{tmp}/in/{rel}"), info(f"{tmp}/out/{rel}")
    assert size in o and kind in o, (rel, o)
    assert size in i and kind in i, (rel, i)
PY
# Metrics: one row per image, means, and the failure.
python3 - "$tmp/out" <<'PY' || fail "metrics"
import csv, json, math, sys
out = sys.argv[1]
rows = list(csv.DictReader(open(f"{out}/render_metrics.csv")))
by = {r["path"]: r for r in rows}
for p in ["chart.png", "a/chart16.tif", "a/b/chart.exr"]:
    assert by[p]["status"] == "rendered", by[p]
    assert 10 < float(by[p]["psnr_db"]) < 60 and 0 < float(by[p]["ssim"]) < 1, by[p]
assert by["a/broken.jpg"]["status"] == "failed" and "corrupt" in by["a/broken.jpg"]["error"]
mean = by["mean"]
psnrs = [float(by[p]["psnr_db"]) for p in ["chart.png", "a/chart16.tif", "a/b/chart.exr"]]
assert abs(float(mean["psnr_db"]) - sum(psnrs) / 3) < 1e-3, (mean, psnrs)
j = json.load(open(f"{out}/render_metrics.json"), parse_constant=lambda x: 1 / 0)
assert j["rendered"] == 3 and j["failed"] == 1 and j["skipped"] == 0
assert abs(j["mean_psnr_db"] - sum(psnrs) / 3) < 1e-3
assert any("broken.jpg" in f for f in j["failed_inputs"])
assert j["settings"]["res_factor"] == 1 and j["settings"]["distortion"] is True
assert j["settings"]["psf"] == {"kind": "geometric"}, j["settings"]
PY

# Resume: nothing is rendered again, the metrics are kept.
touch -d '2000-01-01' "$tmp/out/chart.png"
if "$lensopt" render lenses/cooke.toml "$tmp/in" -o "$tmp/out" -q > "$tmp/stdout2" 2> /dev/null; then
  fail "the resumed run hides the corrupt input"
fi
grep -q "rendered 0, skipped 3 (already there), failed 1" "$tmp/stdout2" || fail "resume: $(cat "$tmp/stdout2")"
[ "$(date -r "$tmp/out/chart.png" +%Y)" = 2000 ] || fail "resume rewrote an existing output"
python3 -c "import json,sys; j=json.load(open(sys.argv[1])); assert j['skipped']==3 and j['mean_psnr_db'] is not None" \
  "$tmp/out/render_metrics.json" || fail "resume lost the metrics"
# --force renders again; single files go to OUT/<name>; 2x and the switches are accepted.
"$lensopt" render lenses/cooke.toml "$tmp/in/chart.png" -o "$tmp/out" --force -q --res-factor 2 \
  --no-distortion --no-ri > "$tmp/stdout3" 2> /dev/null || fail "render --force of one file"
grep -q "rendered 1, skipped 0" "$tmp/stdout3" || fail "force: $(cat "$tmp/stdout3")"
[ "$(date -r "$tmp/out/chart.png" +%Y)" != 2000 ] || fail "--force did not render again"

# Bad output folders and options: a clear message, nothing written.
if "$lensopt" render lenses/cooke.toml "$tmp/in/chart.png" -o "$tmp/in/chart.png" 2> "$tmp/err"; then
  fail "an output folder that is a file was accepted"
fi
grep -qE "not a directory|refusing to write into an input" "$tmp/err" || fail "message: $(cat "$tmp/err")"
if "$lensopt" render lenses/cooke.toml "$tmp/in/chart.png" -o "$tmp/new" --res-factor 3 2> "$tmp/err"; then
  fail "--res-factor 3 accepted"
fi
[ ! -e "$tmp/new" ] || fail "a refused run created its output folder"
if "$lensopt" chart -o "$tmp/c.png" --size 12x12 2> "$tmp/err"; then fail "a 12x12 chart was accepted"; fi
grep -q "32..16384" "$tmp/err" || fail "chart size message: $(cat "$tmp/err")"

# Export: PSFs, grid, maps and per-field values.
"$lensopt" export lenses/tessar.toml -o "$tmp/exp" --image-size 320x180 > /dev/null || fail "export"
for f in psf/field_00.exr psf/field_20.exr psf_sheet.png psf_grid.exr psf_grid.png distortion.exr \
         relative_illumination.exr fields.json; do
  [ -f "$tmp/exp/$f" ] || fail "export lacks $f"
done
python3 - "$tmp/exp/fields.json" <<'PY' || fail "fields.json"
import json, sys
j = json.load(open(sys.argv[1]), parse_constant=lambda x: 1 / 0)
f = j["fields"]
assert len(f) == 21 and f[0]["relative_illumination"] == 1.0
assert f[20]["distortion_percent"] < -4 and 0.7 < f[20]["relative_illumination"] < 0.8
assert all(abs(e - 1) < 1e-9 for e in f[10]["energy_share_rgb"])
assert j["image"]["width"] == 320 and len(j["patches"]) == 81
PY
oiiotool --info "$tmp/exp/psf/field_05.exr" | grep -q "65 x   65, 3 channel, float openexr" || fail "PSF EXR"

# A lens whose relative illumination is unknown (optiland's lens_floa: its on-axis edge rays miss
# a surface) renders without it, and refuses, naming the file and the way out, with it; export
# (which writes the map) refuses before writing anything.
floa=tests/data/zmx-real/optiland_lens_floa.zmx
status=0
"$lensopt" render "$floa" "$tmp/in/chart.png" -o "$tmp/floa" -q 2> "$tmp/floa.err" > /dev/null || status=$?
[ "$status" -eq 1 ] || fail "floa render with relative illumination: exit $status"
grep -q "optiland_lens_floa.zmx: the relative illumination of field 0.00 deg is unknown.*--no-relative-illumination" \
  "$tmp/floa.err" || fail "floa render message: $(cat "$tmp/floa.err")"
"$lensopt" render "$floa" "$tmp/in/chart.png" -o "$tmp/floa_nori" -q --no-relative-illumination \
  > /dev/null 2>&1 || fail "floa render --no-relative-illumination"
[ -f "$tmp/floa_nori/chart.png" ] || fail "floa render --no-relative-illumination: no image"
# Its 12.5 mm spot does not fit the 260 um PSF window: the render says that its blur is cut off;
# the Cooke's spots fit, and nothing is said.
"$lensopt" render "$floa" "$tmp/in/chart.png" -o "$tmp/floa_nori" -q --no-relative-illumination \
  --force > /dev/null 2> "$tmp/floa_window.err" || fail "floa render --force"
grep -q "optiland_lens_floa.zmx: the geometric PSF window (65 x 4 um = 260 um) holds 0.2 % .* field 0.00 deg" \
  "$tmp/floa_window.err" || fail "floa: no PSF window warning: $(cat "$tmp/floa_window.err")"
"$lensopt" render lenses/cooke.toml "$tmp/in/chart.png" -o "$tmp/cooke_window" -q \
  > /dev/null 2> "$tmp/cooke_window.err" || fail "cooke render"
! grep -q "PSF window" "$tmp/cooke_window.err" || fail "cooke: a PSF window warning"
status=0
"$lensopt" export "$floa" -o "$tmp/floa_export" > /dev/null 2>&1 || status=$?
[ "$status" -eq 1 ] || fail "floa export: exit $status"
[ -z "$(ls -A "$tmp/floa_export" 2> /dev/null)" ] || fail "floa export wrote files before failing"

# The sample photo (needs ../shared).
shared="${LENSOPT_SHARED_DIR:-../shared}"
if [ ! -f "$shared/data/images/sample_image.png" ]; then
  echo "skipped: ../shared is absent (sample photo)"; exit 77
fi
"$lensopt" render lenses/tessar.toml "$shared/data/images/sample_image.png" -o "$tmp/photo" -q > "$tmp/p.txt" \
  || fail "render of the sample photo"
oiiotool --info "$tmp/photo/sample_image.png" | grep -q "1664 x  896, 3 channel, uint8 png" || fail "photo output"
echo "render e2e: ok"
