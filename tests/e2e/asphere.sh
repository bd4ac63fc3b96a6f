#!/usr/bin/env bash
# End-to-end tests of `lensopt export` and `lensopt render` on an aspheric lens (issue 16):
# lenses/doublet-asphere.toml (even aspheres on surfaces 1 and 5) against lenses/doublet.toml.
#   export: every output is written; where a field's PSF lies wholly inside its grid (energy
#     share 1 in every channel) the PSF's RMS radius about the grid centre, with the kernel
#     density estimate's variance 2 s^2 taken out (render/psf.h: Gaussian of sigma s per axis,
#     centred on the spot centroid), equals analyze's RMS spot of that field: both sum the same
#     traced rays (32 rings, 15 wavelengths, equal weights per ray) about the same centroid, so
#     the only differences are the sampled Gaussian's second moment (Poisson summation: relative
#     error ~2 exp(-2 pi^2 s^2 / D^2) = 1.4 % of 2 s^2 = 8 um^2, i.e. ~1e-4 of a 39 um spot) and
#     the EXR's float32 values: a 1e-3 relative bound;
#   the aspheric PSF is much smaller on axis than the spherical one (analyze: 39 vs 76 um);
#   render: a chart renders through both, the aspheric image is sharper (higher PSNR and SSIM
#     against the chart) and differs from the spherical one.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
command -v oiiotool > /dev/null || { echo "oiiotool not found: skipped"; exit 77; }

for lens in doublet doublet-asphere; do
  "$lensopt" analyze "lenses/$lens.toml" --json > "$tmp/$lens.json" || fail "analyze $lens"
  "$lensopt" export "lenses/$lens.toml" -o "$tmp/exp-$lens" --image-size 320x180 -j 2 > /dev/null \
    || fail "export $lens"
  for f in psf/field_00.exr psf/field_20.exr psf_sheet.png psf_grid.exr psf_grid.png \
           distortion.exr relative_illumination.exr fields.json; do
    [ -f "$tmp/exp-$lens/$f" ] || fail "export of $lens lacks $f"
  done
done

python3 - "$tmp" <<'PY' || fail "PSF RMS against analyze"
import json, math, re, subprocess, sys
tmp = sys.argv[1]

def psf_rms_um(path, bin_um, grid):
    """RMS radius (um) about the grid centre of the R + G + B PSF, and its total weight."""
    out = subprocess.run(["oiiotool", "--dumpdata", path], capture_output=True, text=True,
                         check=True).stdout
    c = (grid - 1) / 2
    total = second = 0.0
    pixels = 0
    for m in re.finditer(r"Pixel \((\d+), (\d+)\): (\S+) (\S+) (\S+)", out):
        i, r = int(m.group(1)), int(m.group(2))
        w = float(m.group(3)) + float(m.group(4)) + float(m.group(5))
        u, v = (i - c) * bin_um, (c - r) * bin_um
        total += w
        second += w * (u * u + v * v)
        pixels += 1
    assert pixels == grid * grid, (path, pixels)
    return math.sqrt(second / total), total

rms = {}
for lens in ["doublet", "doublet-asphere"]:
    analyze = json.load(open(f"{tmp}/{lens}.json"), parse_constant=lambda x: 1 / 0)
    fields = json.load(open(f"{tmp}/exp-{lens}/fields.json"), parse_constant=lambda x: 1 / 0)
    psf = fields["psf"]
    assert len(fields["fields"]) == len(analyze["rms_spot_um"]) == 21
    assert psf["rings"] == analyze["rings"], (psf, analyze["rings"])
    compared = 0
    for h, field in enumerate(fields["fields"]):
        assert abs(field["field_deg"] - analyze["fields_deg"][h]) < 1e-12
        r, total = psf_rms_um(f"{tmp}/exp-{lens}/{field['psf']}", psf["bin_um"], psf["grid_size"])
        rms[(lens, h)] = r
        # Each channel sums to 1; equal ray counts per channel give every ray equal weight.
        assert abs(total - 3.0) < 1e-4, (lens, h, total)
        assert len(set(field["traced_rays_rgb"])) == 1, field["traced_rays_rgb"]
        if min(field["energy_share_rgb"]) < 1.0 - 1e-6:
            continue  # part of the spot lies outside the grid
        spot = math.sqrt(r * r - 2.0 * psf["sigma_um"] ** 2)
        rel = spot / analyze["rms_spot_um"][h] - 1.0
        assert abs(rel) < 1e-3, (lens, h, spot, analyze["rms_spot_um"][h], rel)
        compared += 1
    print(f"{lens}: {compared} fields compared with analyze")
    if lens == "doublet-asphere":
        assert compared >= 5, compared
# The aspheres halve the on-axis spot (analyze: 39 vs 76 um); the PSFs must show it.
assert rms[("doublet-asphere", 0)] < 0.7 * rms[("doublet", 0)], rms
PY

# Render a chart through both lenses.
mkdir -p "$tmp/in"
"$lensopt" chart -o "$tmp/in/chart.png" --size 240x160 > /dev/null || fail "chart"
for lens in doublet doublet-asphere; do
  "$lensopt" render "lenses/$lens.toml" "$tmp/in" -o "$tmp/render-$lens" --jobs 2 -q > /dev/null \
    || fail "render $lens"
  [ -f "$tmp/render-$lens/chart.png" ] || fail "render of $lens wrote no image"
done
cmp -s "$tmp/render-doublet/chart.png" "$tmp/render-doublet-asphere/chart.png" \
  && fail "the aspheric and spherical renders are identical"
python3 - "$tmp" <<'PY' || fail "render metrics"
import json, sys
tmp = sys.argv[1]
m = {l: json.load(open(f"{tmp}/render-{l}/render_metrics.json"), parse_constant=lambda x: 1 / 0)
     for l in ["doublet", "doublet-asphere"]}
for l, j in m.items():
    assert j["rendered"] == 1 and j["failed"] == 0, (l, j)
s, a = m["doublet"], m["doublet-asphere"]
assert a["mean_psnr_db"] > s["mean_psnr_db"] + 0.5, (a["mean_psnr_db"], s["mean_psnr_db"])
assert a["mean_ssim"] > s["mean_ssim"], (a["mean_ssim"], s["mean_ssim"])
PY
echo "asphere e2e: ok"
