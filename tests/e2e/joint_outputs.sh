#!/usr/bin/env bash
# End-to-end test of the output checks of `lensopt optimize --joint` (issue 15): before any work
# (no training, no file written, no progress line) a run is refused, naming the file, when an
# output (the lens, --log, --network, --checkpoint-dir) is an input of the same run (the lens,
# the training images, a TorchScript task's module, the checkpoint resumed from), when two outputs
# are the same file, or when an output's folder does not exist. Without libtorch --joint says so
# and the test is skipped (exit 77).
set -euo pipefail
lensopt="$1"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
# A run the checks failed to stop must still end soon (one step, tiny sampling).
tiny=(--steps 1 --decay-steps 0 --scenes 1 --scene-width 128 --scene-height 96 --crop 32 --batch 1
      --eval-crops 1 --psf-rings 2 --psf-fields 3 --design-rings 2 --design-fields 3 --features 4
      --layers 2)
cp lenses/doublet.toml "$tmp/lens.toml"
mkdir -p "$tmp/images" "$tmp/ckpt"
"$lensopt" chart -o "$tmp/images/a.png" --size 160x120 > /dev/null
cp "$tmp/lens.toml" "$tmp/lens.orig"

# refused EXPECTED_TEXT NAMED_FILE ARGS...: the run fails at once with one message naming the file.
refused() {
  local expect=$1 named=$2
  shift 2
  rm -f "$tmp/out.toml" "$tmp/out.csv" "$tmp/out.network.pt"
  if "$lensopt" optimize "$tmp/lens.toml" --joint "${tiny[@]}" "$@" > "$tmp/stdout" 2> "$tmp/err"; then
    fail "accepted: $*"
  fi
  if grep -q "built without" "$tmp/err"; then
    echo "skipped: lensopt was built without libtorch"
    exit 77
  fi
  grep -q -- "$expect" "$tmp/err" || fail "$*: message $(cat "$tmp/err"), expected '$expect'"
  grep -q -- "$named" "$tmp/err" || fail "$*: the message does not name $named: $(cat "$tmp/err")"
  [ "$(wc -l < "$tmp/err")" -eq 1 ] || fail "$*: work was done before the refusal: $(cat "$tmp/err")"
  [ ! -s "$tmp/stdout" ] || fail "$*: printed $(cat "$tmp/stdout")"
  for f in out.toml out.csv out.network.pt new-ckpt; do
    [ ! -e "$tmp/$f" ] || fail "$*: $f was written"
  done
  cmp -s "$tmp/lens.toml" "$tmp/lens.orig" || fail "$*: the input lens was changed"
  [ -z "$(find "$tmp" -name '.*tmp*')" ] || fail "$*: temporary files left"
}

refused "over an input" lens.toml -o "$tmp/out.toml" --log "$tmp/lens.toml"
refused "over an input" lens.toml -o "$tmp/out.toml" --network "$tmp/lens.toml"
refused "over an input" lens.toml --in-place --log "$tmp/lens.toml"
refused "over an input" out.toml -o "$tmp/out.toml" --log "$tmp/out.toml"
refused "over an input" out.csv -o "$tmp/out.toml" --network "$tmp/out.csv" --log "$tmp/out.csv"
refused "over an input" model.pt -o "$tmp/out.toml" --task "torchscript:$tmp/model.pt" --network "$tmp/model.pt"
refused "into an input" images -o "$tmp/out.toml" --images "$tmp/images" --checkpoint-every 1 \
  --checkpoint-dir "$tmp/images"
refused "it is a directory" ckpt -o "$tmp/out.toml" --resume "$tmp/ckpt" --log "$tmp/ckpt"
refused "does not exist" missing -o "$tmp/missing/out.toml"
refused "does not exist" missing -o "$tmp/out.toml" --network "$tmp/missing/net.pt"
refused "does not exist" missing -o "$tmp/out.toml" --log "$tmp/missing/log.csv"
echo text > "$tmp/file.txt"
refused "not a directory" file.txt -o "$tmp/out.toml" --checkpoint-every 1 --checkpoint-dir "$tmp/file.txt"
echo "joint output checks: ok"
