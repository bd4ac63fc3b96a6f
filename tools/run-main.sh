#!/usr/bin/env bash
# README's main job: install dependencies, build, then analyse, optimize (alone and jointly with
# a restoration network), search, tolerance, render and plot the lenses, catalog and chart that
# ship with the project. Outputs in out/.
set -euo pipefail
cd "$(dirname "$0")/.."
tools/install-deps.sh
# The command-line tool and the modules it loads; tools/test.sh builds the rest (tests, Python).
LENSOPT_TARGETS=lensopt tools/build.sh
lensopt=build/lensopt
mkdir -p out
has() { "$lensopt" "$1" --help >/dev/null 2>&1 && ! "$lensopt" "$1" --help 2>&1 | grep -q "not built yet"; }

echo "== glass catalog"
"$lensopt" catalog ohara --wavelengths-nm 486.1327,587.5618,656.2725 > out/catalog.txt
head -8 out/catalog.txt
echo "== analysis of the paper's baselines"
for lens in lenses/doublet.toml lenses/cooke.toml lenses/tessar.toml; do
  "$lensopt" analyze "$lens" --json > "out/$(basename "$lens" .toml)-analysis.json"
  "$lensopt" analyze "$lens" | grep -E "^Lens|mean RMS spot|focal length"
done
echo "== tracer benchmark"
"$lensopt" bench
echo "== optimization (Doublet, Levenberg-Marquardt)"
"$lensopt" optimize lenses/doublet.toml -o out/doublet-optimized.toml -q
echo "== joint optimization (Doublet + restoration network, a short run of 30 steps per setting)"
"$lensopt" optimize lenses/doublet.toml --joint --steps 30 --crop 128 --eval-crops 8 \
  -o out/doublet-joint.toml -q
echo "== tolerancing (Tessar, 2000 trials)"
"$lensopt" tolerance lenses/tessar.toml --trials 2000 --seed 1 --csv out/tessar-trials.csv \
  --histogram out/tessar-histogram.svg > out/tessar-tolerance.txt
head -20 out/tessar-tolerance.txt
echo "== baseline search (Doublet: stop in front, between, behind; two glass seeds)"
"$lensopt" search lenses/doublet.toml --vary-stop --glass-seeds 2 -o out/search-doublet -q
if has chart && has render; then
  echo "== image simulation of the generated chart"
  "$lensopt" chart -o out/chart.png --size 1280x720
  for lens in doublet cooke tessar; do
    "$lensopt" render "lenses/$lens.toml" out/chart.png -o "out/render-$lens" --force
  done
fi
if has plot; then
  echo "== plots"
  for lens in doublet cooke tessar; do
    "$lensopt" plot "lenses/$lens.toml" --kind report -o "out/$lens-report.svg"
  done
fi
echo "main job done: outputs in out/"
