#!/usr/bin/env bash
# End-to-end test of `lensopt optimize LENS --joint --task detection --data DIR` (issue 19): on a
# tiny generated dataset (`lensopt chart --detection`) one command runs the paper's four settings
# and prints them as a table (text, and JSON with --json: perfect optics without mean spot, PSNR
# and SSIM; AP, AP50, AP75 for every setting); it writes the lens, the log and the perfect-optics
# detector, and a second run of another lens reuses that detector (--detector) instead of training
# it again (only the perfect-optics row's continuation, --steps on sharp crops, is trained). Tiny sampling and a few steps keep it to seconds. Without libtorch it is skipped (exit 77).
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
"$lensopt" chart --detection -o "$tmp/data" --count 5 --size 192x112 --seed 3 > /dev/null
tiny=(--task detection --data "$tmp/data" --steps 2 --decay-steps 1 --crop 64 --batch 2
      --eval-crops 2 --psf-rings 3 --psf-fields 3 --design-rings 3 --design-fields 3
      --res-factor 2 --holdout 0.4)
if ! "$lensopt" optimize lenses/doublet.toml --joint "${tiny[@]}" -o "$tmp/out.toml" \
    > "$tmp/text" 2> "$tmp/err"; then
  if grep -q "built without" "$tmp/err"; then
    echo "skipped: lensopt was built without libtorch"
    exit 77
  fi
  fail "the detection run failed: $(cat "$tmp/err")"
fi
cat "$tmp/text"
for f in out.toml out.csv out.detector.pt out.network.pt; do
  [ -s "$tmp/$f" ] || fail "$f was not written"
done
for row in "perfect " "fixed/fixed" "fixed/trained" "joint "; do
  grep -q "^  $row" "$tmp/text" || fail "no '$row' row in the table"
done
grep -q "mean spot (um) *PSNR (dB) *SSIM *AP *AP50 *AP75" "$tmp/text" || fail "no table header"
# Perfect optics has no lens: its spot, PSNR and SSIM are '-'.
grep -E -q "^  perfect +- +- +- +[0-9.-]+" "$tmp/text" || fail "perfect row: $(grep perfect "$tmp/text")"
# Perfect optics: the base detector (--perfect-steps, default --steps: 2), then --steps (2) more.
[ "$(grep -c '^perfect,' "$tmp/out.csv")" -eq 4 ] || fail "the log has no 2 + 2 perfect-optics steps"

# Another lens, the same base detector: only the perfect row's continuation (2 steps) is trained,
# and its AP is the first run's (the same continuation on the same crops, the same held-out crops).
"$lensopt" optimize lenses/tessar.toml --joint "${tiny[@]}" --detector "$tmp/out.detector.pt" \
  -o "$tmp/tessar.toml" --json > "$tmp/tessar.json" 2> "$tmp/err2" || fail "$(cat "$tmp/err2")"
python3 - "$tmp/text" "$tmp/tessar.json" "$tmp/tessar.csv" <<'PY'
import json, sys
text = open(sys.argv[1]).read()
j = json.load(open(sys.argv[2]))
names = [s["name"] for s in j["settings"]]
assert names == ["perfect", "fixed/fixed", "fixed/trained", "joint"], names
perfect = j["settings"][0]
assert perfect["mean_spot_um"] is None and perfect["psnr_db"] is None and perfect["ssim"] is None, perfect
for s in j["settings"]:
    for k in ("ap", "ap50", "ap75"):
        assert s[k] is None or -1 <= s[k] <= 1, s
    if s["name"] != "perfect":
        assert s["mean_spot_um"] > 0 and s["psnr_db"] > 10 and 0 < s["ssim"] <= 1, s
first = [l for l in text.splitlines() if l.startswith("  perfect ")][0].split()
ap_text = float(first[4])
assert perfect["ap"] is not None and abs(perfect["ap"] - ap_text) < 6e-5, (perfect["ap"], ap_text)
assert j["res_factor"] == 2 and j["distortion"] is True, j
rows = [l.split(",")[1] for l in open(sys.argv[3]) if l.startswith("perfect,")]
assert rows == ["2", "3"], ("the reused detector was trained again", rows)
print("joint detection: table and JSON agree; perfect AP", ap_text, "reused")
PY
echo "e2e joint_detection: ok"
