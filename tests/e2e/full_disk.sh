#!/usr/bin/env bash
# End-to-end full-disk test (issue 15): every command that writes files runs under an LD_PRELOAD
# shim (tests/shim/failwrite.c) that makes writes to regular files fail with ENOSPC after N
# bytes. Each must exit non-zero naming the file it could not write, leave no partial or 0-byte
# file under a final name and no temporary; a rerun without the shim must produce every output,
# identical to a run that never saw a full disk.
set -euo pipefail
lensopt="$1"
shim="${LENSOPT_FAILWRITE_SHIM:-$(dirname "$lensopt")/liblensopt_failwrite.so}"
[ -f "$shim" ] || { echo "skipped: no fault-injection shim ($shim)"; exit 77; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# full BYTES NAME_IN_MESSAGE DIR COMMAND...: runs COMMAND with the disk "full" after BYTES.
full() {
  local bytes=$1 name=$2 dir=$3
  shift 3
  local status=0
  LD_PRELOAD="$shim" LENSOPT_FAIL_WRITE_AFTER="$bytes" "$lensopt" "$@" > "$tmp/stdout" 2> "$tmp/stderr" ||
    status=$?
  [ "$status" -ne 0 ] || fail "$1 exited 0 on a full disk"
  [ "$status" -ne 2 ] || fail "$1: internal error on a full disk: $(cat "$tmp/stderr")"
  grep -q "$name" "$tmp/stderr" || fail "$1: the message does not name $name: $(cat "$tmp/stderr")"
  grep -q "cannot write" "$tmp/stderr" || fail "$1: no reason: $(cat "$tmp/stderr")"
  [ -z "$(find "$dir" -type f -size 0)" ] || fail "$1: 0-byte files: $(find "$dir" -type f -size 0)"
  [ -z "$(find "$dir" -name '.*tmp*')" ] || fail "$1: temporaries left: $(find "$dir" -name '.*tmp*')"
}
# same A B: the files present in A are identical to B's.
same() {
  (cd "$1" && find . -type f ! -name 'render_metrics.*' ! -name '.*') | while read -r f; do
    cmp -s "$1/$f" "$2/$f" || fail "$1/$f is partial or differs from $2/$f"
  done
}

mkdir -p "$tmp/ref" "$tmp/a"

# chart
"$lensopt" chart -o "$tmp/ref/c.png" --size 240x160 > /dev/null
full 2000 "c.png" "$tmp/a" chart -o "$tmp/a/c.png" --size 240x160
[ ! -e "$tmp/a/c.png" ] || fail "chart: a partial c.png"
"$lensopt" chart -o "$tmp/a/c.png" --size 240x160 > /dev/null || fail "chart rerun"
cmp -s "$tmp/a/c.png" "$tmp/ref/c.png" || fail "chart rerun differs"

# plot (PNG and SVG)
for ext in png svg; do
  full 3000 "p.$ext" "$tmp/a" plot lenses/doublet.toml -o "$tmp/a/p.$ext"
  [ ! -e "$tmp/a/p.$ext" ] || fail "plot: a partial p.$ext"
  "$lensopt" plot lenses/doublet.toml -o "$tmp/a/p.$ext" 2> /dev/null || fail "plot rerun"
  [ -s "$tmp/a/p.$ext" ] || fail "plot rerun wrote nothing"
done

# convert (TOML and .zmx)
for ext in toml zmx; do
  full 100 "d.$ext" "$tmp/a" convert lenses/doublet.toml "$tmp/a/d.$ext"
  [ ! -e "$tmp/a/d.$ext" ] || fail "convert: a partial d.$ext"
  "$lensopt" convert lenses/doublet.toml "$tmp/a/d.$ext" > /dev/null || fail "convert rerun"
  "$lensopt" convert lenses/doublet.toml "$tmp/ref/d.$ext" > /dev/null
  cmp -s "$tmp/a/d.$ext" "$tmp/ref/d.$ext" || fail "convert rerun differs"
done

# optimize -o
opt=(optimize lenses/doublet.toml --max-iterations 2 --rings 3 --fields 3 --quiet)
full 100 "o.toml" "$tmp/a" "${opt[@]}" -o "$tmp/a/o.toml"
[ ! -e "$tmp/a/o.toml" ] || fail "optimize: a partial o.toml"
"$lensopt" "${opt[@]}" -o "$tmp/a/o.toml" > /dev/null || fail "optimize rerun"
[ -s "$tmp/a/o.toml" ] || fail "optimize rerun wrote nothing"

# tolerance --csv --histogram: the CSV fits, the histogram does not
tol=(tolerance lenses/doublet.toml --trials 20 --rings 3 --fields 3 --no-sensitivity --quiet)
"$lensopt" "${tol[@]}" --csv "$tmp/ref/t.csv" --histogram "$tmp/ref/h.svg" > /dev/null
csv_bytes=$(stat -c %s "$tmp/ref/t.csv")
full $((csv_bytes + 50)) "h.svg" "$tmp/a" "${tol[@]}" --csv "$tmp/a/t.csv" --histogram "$tmp/a/h.svg"
[ ! -e "$tmp/a/h.svg" ] || fail "tolerance: a partial h.svg"
"$lensopt" "${tol[@]}" --csv "$tmp/a/t.csv" --histogram "$tmp/a/h.svg" > /dev/null || fail "tolerance rerun"
cmp -s "$tmp/a/t.csv" "$tmp/ref/t.csv" && cmp -s "$tmp/a/h.svg" "$tmp/ref/h.svg" || fail "tolerance rerun differs"

# export
full 5000 "$tmp/a/ex/" "$tmp/a" export lenses/cooke.toml -o "$tmp/a/ex" --image-size 160x96
"$lensopt" export lenses/cooke.toml -o "$tmp/a/ex" --image-size 160x96 > /dev/null || fail "export rerun"
"$lensopt" export lenses/cooke.toml -o "$tmp/ref/ex" --image-size 160x96 > /dev/null
# (EXR bytes are not reproducible run to run: the same file names, each one decoding.)
[ "$(cd "$tmp/ref/ex" && find . -type f | sort)" = "$(cd "$tmp/a/ex" && find . -type f | sort)" ] ||
  fail "export rerun: other files"
if command -v oiiotool > /dev/null; then
  for f in $(cd "$tmp/a/ex" && find . -name '*.exr' -o -name '*.png'); do
    oiiotool "$tmp/a/ex/$f" --printstats > /dev/null 2>&1 || fail "export: $f does not decode"
  done
fi

# render: the first image fits, the others and the metrics do not
mkdir -p "$tmp/in"
for i in 0 1 2 3; do "$lensopt" chart -o "$tmp/in/c$i.png" --size "$((200 + 4 * i))x120" > /dev/null; done
"$lensopt" render lenses/cooke.toml "$tmp/in" -o "$tmp/ref/r" --jobs 1 -q > /dev/null
first=$(stat -c %s "$tmp/ref/r/c0.png")
full $((first + 300)) "render_metrics" "$tmp/a" render lenses/cooke.toml "$tmp/in" -o "$tmp/a/r" --jobs 1 -q
grep -q "$tmp/a/r/c1.png" "$tmp/stderr" || fail "render: the failed image is not named: $(cat "$tmp/stderr")"
same "$tmp/a/r" "$tmp/ref/r"
"$lensopt" render lenses/cooke.toml "$tmp/in" -o "$tmp/a/r" --jobs 1 -q > "$tmp/stdout" || fail "render rerun"
grep -q "failed 0" "$tmp/stdout" || fail "render rerun: $(cat "$tmp/stdout")"
same "$tmp/ref/r" "$tmp/a/r"
[ -s "$tmp/a/r/render_metrics.csv" ] && [ -s "$tmp/a/r/render_metrics.json" ] || fail "render rerun: no metrics"

# search -o
srch=(search lenses/doublet.toml --glass-seeds 1 --rings 3 --fields 3 --max-iterations 2 --max-rounds 1 --top 1 -q --jobs 1)
full 200 "$tmp/a/s/" "$tmp/a" "${srch[@]}" -o "$tmp/a/s"
"$lensopt" "${srch[@]}" -o "$tmp/a/s" > /dev/null || fail "search rerun"
[ -s "$tmp/a/s/leaderboard.csv" ] || fail "search rerun: no leaderboard"
echo "ok"
