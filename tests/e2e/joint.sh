#!/usr/bin/env bash
# End-to-end tests of `lensopt optimize --joint`: a tiny run writes the lens (readable by
# analyze), the per-step CSV and the network, and reports the three settings as JSON; a run
# stopped after some steps and resumed from its checkpoint writes the same CSV as a straight run.
# Without libtorch, --joint must say so (and the rest is skipped: exit 77).
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
tiny=(--scenes 3 --scene-width 160 --scene-height 120 --crop 32 --batch 2 --eval-crops 2
      --psf-rings 4 --psf-fields 5 --design-rings 4 --design-fields 3 --features 8 --layers 3
      --steps 4 --decay-steps 2 -q)

if ! "$lensopt" optimize lenses/doublet.toml --joint -o "$tmp/out.toml" --json "${tiny[@]}" \
    > "$tmp/report.json" 2> "$tmp/err.txt"; then
  if grep -q "built without" "$tmp/err.txt"; then
    echo "skipped: lensopt was built without libtorch ($(cat "$tmp/err.txt"))"
    exit 77
  fi
  fail "joint run: $(cat "$tmp/err.txt")"
fi
python3 - "$tmp/report.json" "$tmp/out.csv" <<'PY' || fail "joint JSON / CSV"
import csv, json, sys
def no_nan(x): raise ValueError("NaN in JSON")
r = json.load(open(sys.argv[1]), parse_constant=no_nan)
names = [s["name"] for s in r["settings"]]
assert names == ["fixed/fixed", "fixed/trained", "joint"], names
assert "joint_minus_fixed_trained" in r
assert r["metric"] == "PSNR (dB)", r["metric"]
rows = list(csv.DictReader(open(sys.argv[2])))
assert len(rows) == 8, len(rows)          # 4 fixed/trained + 4 joint steps
assert {row["phase"] for row in rows} == {"fixed/trained", "joint"}
assert float(rows[-1]["lr_lens"]) < float(rows[4]["lr_lens"])  # decayed
assert all(row["glass1"] and row["glass2"] for row in rows)
PY
"$lensopt" analyze "$tmp/out.toml" --json > /dev/null || fail "the joint lens does not read back"
[ -s "$tmp/out.network.pt" ] || fail "no network file"
ls -a "$tmp" | grep -q '\.tmp' && fail "a temporary file was left behind"

# Stop after 5 steps with checkpoints, resume: the same CSV as the straight run.
if "$lensopt" optimize lenses/doublet.toml --joint -o "$tmp/r.toml" "${tiny[@]}" \
    --checkpoint-every 1 --stop-after 5 2> "$tmp/err.txt"; then
  fail "a stopped run should exit nonzero"
fi
grep -q -- "--resume" "$tmp/err.txt" || fail "stop message: $(cat "$tmp/err.txt")"
[ -e "$tmp/r.toml" ] && fail "a stopped run wrote the lens"
"$lensopt" optimize lenses/doublet.toml --joint -o "$tmp/r.toml" "${tiny[@]}" \
  --checkpoint-every 1 --resume "$tmp/r.checkpoint" > /dev/null || fail "resume"
cmp -s "$tmp/out.csv" "$tmp/r.csv" || fail "resumed CSV differs: $(diff "$tmp/out.csv" "$tmp/r.csv" | head -5)"

# Bad input: an unknown task is named.
if "$lensopt" optimize lenses/doublet.toml --joint -o "$tmp/x.toml" "${tiny[@]}" \
    --task frobnicate 2> "$tmp/err.txt"; then
  fail "unknown task accepted"
fi
grep -q "unknown task 'frobnicate'" "$tmp/err.txt" || fail "unknown task message: $(cat "$tmp/err.txt")"
# libtorch is a module loaded by --joint only (src/joint/torch_plugin.h): the executable does not
# link it, and a module that cannot be loaded is a clear error before any output is written.
if ldd "$lensopt" | grep -q "libtorch"; then fail "lensopt links libtorch: $(ldd "$lensopt" | grep libtorch)"; fi
if LENSOPT_TORCH_PLUGIN="$tmp/missing.so" "$lensopt" optimize lenses/doublet.toml --joint \
    -o "$tmp/missing.toml" "${tiny[@]}" 2> "$tmp/missing.txt"; then
  fail "--joint with a missing libtorch module exited 0"
fi
grep -q "LENSOPT_TORCH_PLUGIN=$tmp/missing.so" "$tmp/missing.txt" || fail "no module path in: $(cat "$tmp/missing.txt")"
[ -e "$tmp/missing.toml" ] && fail "a lens was written although the module did not load"
echo "joint: ok"
