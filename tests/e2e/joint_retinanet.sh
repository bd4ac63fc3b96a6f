#!/usr/bin/env bash
# End-to-end test of tools/export-retinanet.py with `lensopt optimize --joint --task
# torchscript:FILE` (issue 19): torchvision's RetinaNet-ResNet50-FPN (random weights, resized
# internally to 64 px to keep it to seconds) is exported to the TorchScript detection contract and
# trained jointly with the Doublet for one step on a tiny generated dataset; the detector's loss
# reaches the lens and the scores are well formed. About 25 CPU-seconds. Skipped (exit 77) without
# a Python that has torchvision (Debian: python3-torchvision) or without libtorch.
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
python=""
for candidate in /usr/bin/python3 python3; do
  if command -v "$candidate" > /dev/null && "$candidate" -c "import torchvision" 2> /dev/null; then
    python="$candidate"
    break
  fi
done
if [ -z "$python" ]; then
  echo "skipped: no python3 with torchvision (apt-get install python3-torchvision)"
  exit 77
fi
OMP_NUM_THREADS=1 "$python" tools/export-retinanet.py -o "$tmp/retinanet.pt" --min-size 64 \
  --max-size 64 > "$tmp/export" 2>&1 || fail "export: $(cat "$tmp/export")"
[ -s "$tmp/retinanet.pt" ] || fail "the export wrote nothing"
"$lensopt" chart --detection -o "$tmp/data" --count 5 --size 192x112 --seed 3 > /dev/null
if ! "$lensopt" optimize lenses/doublet.toml --joint --task "torchscript:$tmp/retinanet.pt" \
    --data "$tmp/data" --steps 1 --decay-steps 0 --crop 64 --batch 2 --eval-crops 1 \
    --psf-rings 3 --psf-fields 3 --design-rings 3 --design-fields 3 --res-factor 2 \
    --holdout 0.4 --threads 1 --only-joint --json -o "$tmp/out.toml" > "$tmp/out.json" \
    2> "$tmp/err"; then
  if grep -q "built without" "$tmp/err"; then
    echo "skipped: lensopt was built without libtorch"
    exit 77
  fi
  fail "the RetinaNet run failed: $(cat "$tmp/err")"
fi
for f in out.toml out.csv out.detector.pt out.network.pt; do
  [ -s "$tmp/$f" ] || fail "$f was not written"
done
python3 - "$tmp/out.json" "$tmp/out.csv" <<'PY'
import csv, json, math, sys
j = json.load(open(sys.argv[1]))
names = [s["name"] for s in j["settings"]]
assert names == ["perfect", "joint"], names
for s in j["settings"]:
    assert s["ap"] is None or -1 <= s["ap"] <= 1, s
joint = j["settings"][1]
assert joint["mean_spot_um"] > 0 and joint["psnr_db"] > 10 and 0 < joint["ssim"] <= 1, joint
rows = list(csv.DictReader(open(sys.argv[2])))
# perfect optics: 1 base step + 1 continuation step; joint: 1 step
assert [r["phase"] for r in rows] == ["perfect", "perfect", "joint"], [r["phase"] for r in rows]
for r in rows:
    assert math.isfinite(float(r["loss_task"])) and float(r["loss_task"]) > 0, r
# RetinaNet's loss reaches the lens variables through the rendered images.
assert float(rows[2]["grad_norm_task"]) > 0, rows[2]
print("joint RetinaNet: one step, task loss", rows[2]["loss_task"])
PY
echo "e2e joint_retinanet: ok"
