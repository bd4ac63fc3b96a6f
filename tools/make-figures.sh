#!/usr/bin/env bash
# Generates every `lensopt plot` kind for the three baseline lenses (lenses/doublet.toml,
# cooke.toml, tessar.toml), plus Tessar-vs-Doublet comparisons, into OUTDIR.
#   OUTDIR/<lens>_<kind>.png   kind = layout, spot, fan, field, psf, report
#   OUTDIR/<lens>_report.svg, OUTDIR/<lens>_layout.svg   the same as SVG
#   OUTDIR/compare_layout.png  Tessar (solid) over Doublet (dashed), image planes aligned
#   OUTDIR/compare_spot.png    Tessar and Doublet spot diagrams on one scale
#   OUTDIR/tessar_<kind>.png   kind = mtf-field, chromatic, encircled-energy
# Spot diagrams and reports share one box size (SPOT_BOX_UM, default 600 um) so the baselines
# can be compared page against page.
# Usage: tools/make-figures.sh LENSOPT_EXE OUTDIR
set -euo pipefail
lensopt=${1:?usage: make-figures.sh LENSOPT_EXE OUTDIR}
outdir=${2:?usage: make-figures.sh LENSOPT_EXE OUTDIR}
root=$(cd "$(dirname "$0")/.." && pwd)
box=${SPOT_BOX_UM:-600}
mkdir -p "$outdir"

plot() {
  echo "make-figures: $*" >&2
  "$lensopt" plot "$@"
}

for lens in doublet cooke tessar; do
  file="$root/lenses/$lens.toml"
  for kind in layout spot fan field psf report; do
    plot "$file" --kind "$kind" --spot-box-um "$box" -o "$outdir/${lens}_${kind}.png"
  done
  plot "$file" --kind report --spot-box-um "$box" -o "$outdir/${lens}_report.svg"
  plot "$file" --kind layout -o "$outdir/${lens}_layout.svg"
done
# The designer's charts of the Tessar (docs/plots.md shows them).
for kind in mtf-field chromatic encircled-energy; do
  plot "$root/lenses/tessar.toml" --kind "$kind" -o "$outdir/tessar_${kind}.png"
done
plot "$root/lenses/tessar.toml" --kind layout --compare "$root/lenses/doublet.toml" \
  -o "$outdir/compare_layout.png"
plot "$root/lenses/tessar.toml" --kind spot --compare "$root/lenses/doublet.toml" \
  --spot-box-um "$box" -o "$outdir/compare_spot.png"
echo "make-figures: wrote $(ls "$outdir" | wc -l) files to $outdir" >&2
