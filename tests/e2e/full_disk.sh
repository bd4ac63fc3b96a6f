#!/usr/bin/env bash
# End-to-end full-disk test (issues 15 and 34): every command that writes files runs under an
# LD_PRELOAD shim (tests/shim/failwrite.c) that makes writes to regular files fail with ENOSPC
# after N bytes, for N = 0 %, 5 %, 35 % and 75 % of the bytes its outputs need (the sizes of a
# reference run's files). Each run must exit non-zero naming the file it could not write, leave
# no 0-byte file and no temporary, and every output it did leave under its final name must be
# complete (equal to the reference's). A rerun without the shim (the space freed) must then
# produce every output, equal to a run that never saw a full disk:
#   - search resumes from the results/ files the failed run finished; its outputs equal the
#     reference's but for the wall-time columns (seconds), which no two runs share;
#   - render resumes from its journal: a failed run that finished images leaves
#     OUT/.render_metrics.journal (the completion records, docs/render.md "Resume"), the rerun
#     skips exactly the images it records, renders the others, writes the metrics and removes it;
#   - export's EXR files are not byte-reproducible run to run: the same names, each decoding.
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
  [ "$status" -ne 0 ] || fail "$1 exited 0 on a full disk ($bytes bytes)"
  [ "$status" -ne 2 ] || fail "$1: internal error on a full disk: $(cat "$tmp/stderr")"
  [ "$status" -lt 128 ] || fail "$1: signal $((status - 128)) on a full disk: $(cat "$tmp/stderr")"
  grep -q "$name" "$tmp/stderr" || fail "$1: the message does not name $name: $(cat "$tmp/stderr")"
  grep -q "cannot write" "$tmp/stderr" || fail "$1: no reason: $(cat "$tmp/stderr")"
  [ -z "$(find "$dir" -type f -size 0)" ] || fail "$1: 0-byte files: $(find "$dir" -type f -size 0)"
  [ -z "$(find "$dir" -name '.*tmp*')" ] || fail "$1: temporaries left: $(find "$dir" -name '.*tmp*')"
}

# The text of an output with its wall-time fields masked (search's "seconds" and the CSV's last
# column, render's metrics are not compared).
masked() {
  case "$1" in
    *.json) sed -E 's/"seconds": [-0-9.e+]+/"seconds": S/' "$1" ;;
    *.csv) sed -E 's/,[-0-9.e+]+$/,S/' "$1" ;;
    *) cat "$1" ;;
  esac
}

# same MODE A B: each output file in A (not hidden) is complete: equal to B's (MODE exact: byte
# for byte; masked: but for wall times; render: the images byte for byte, metrics skipped; export:
# PNG byte for byte, EXR decoding).
same() {
  local mode=$1 a=$2 b=$3 f
  while read -r f; do
    [ -n "$f" ] || continue
    [ -f "$b/$f" ] || fail "$a/$f: not an output of the reference run"
    case "$mode:$f" in
      render:*render_metrics*) ;;
      export:*.exr)
        if command -v oiiotool > /dev/null; then
          oiiotool "$a/$f" --printstats > /dev/null 2>&1 || fail "$a/$f does not decode"
        fi
        ;;
      masked:*) cmp -s <(masked "$a/$f") <(masked "$b/$f") || fail "$a/$f is partial or differs from $b/$f" ;;
      *) cmp -s "$a/$f" "$b/$f" || fail "$a/$f is partial or differs from $b/$f" ;;
    esac
  done < <(cd "$a" && find . -type f ! -name '.*' | sort)
}

# every MODE REF DIR: DIR holds every output of REF, complete, and nothing else.
every() {
  [ "$(cd "$2" && find . -type f ! -name '.*' | sort)" = "$(cd "$3" && find . -type f ! -name '.*' | sort)" ] ||
    fail "$3: other files than $2: $(diff <(cd "$2" && find . -type f | sort) <(cd "$3" && find . -type f | sort) | tr '\n' ' ')"
  same "$1" "$3" "$2"
}

journal_seen=0
# check NAME MODE ARGS...: ARGS with @OUT@ for the case's output folder (render writes to
# @OUT@/r). A reference run, then for each fraction a run on a full disk and a rerun.
check() {
  local name=$1 mode=$2
  shift 2
  local ref="$tmp/$name/ref"
  mkdir -p "$ref"
  "$lensopt" "${@//@OUT@/$ref}" > /dev/null 2>&1 || fail "$name: the reference run failed"
  local need
  need=$(find "$ref" -type f -printf '%s\n' | awk '{s += $1} END {print s + 0}')
  for pct in 0 5 35 75; do
    local dir="$tmp/$name/p$pct"
    local bytes=$((need * pct / 100))
    mkdir -p "$dir"
    full "$bytes" "$dir/" "$dir" "${@//@OUT@/$dir}"
    same "$mode" "$dir" "$ref"
    local records=-1 journal="$dir/r/.render_metrics.journal"
    if [ "$mode" = render ] && [ -f "$journal" ]; then
      # The resume journal: one complete line per image whose rename it records.
      records=$(tr -cd '\n' < "$journal" | wc -c)
      journal_seen=$((journal_seen + 1))
    fi
    "$lensopt" "${@//@OUT@/$dir}" > "$tmp/stdout" 2> "$tmp/stderr" ||
      fail "$name at $pct % ($bytes of $need bytes): the rerun failed: $(cat "$tmp/stderr")"
    every "$mode" "$ref" "$dir"
    if [ "$mode" = render ]; then
      grep -q "failed 0" "$tmp/stdout" || fail "$name rerun at $pct %: $(cat "$tmp/stdout")"
      [ "$records" -lt 0 ] || grep -q "skipped $records (already there)" "$tmp/stdout" ||
        fail "$name rerun at $pct %: the journal recorded $records images: $(cat "$tmp/stdout")"
      [ ! -e "$journal" ] || fail "$name rerun at $pct %: the journal is left"
      [ -s "$dir/r/render_metrics.csv" ] && [ -s "$dir/r/render_metrics.json" ] || fail "$name: no metrics"
    fi
    local note=""
    [ "$records" -lt 0 ] || note=" (resumed from the journal: $records images skipped)"
    echo "  $name: $pct % ($bytes of $need bytes): refused, rerun complete$note"
  done
}

check chart exact chart -o @OUT@/c.png --size 240x160
check plot-png exact plot lenses/doublet.toml -o @OUT@/p.png
check plot-svg exact plot lenses/doublet.toml -o @OUT@/p.svg
check convert-toml exact convert lenses/doublet.toml @OUT@/d.toml
check convert-zmx exact convert lenses/doublet.toml @OUT@/d.zmx
check optimize exact optimize lenses/doublet.toml --max-iterations 2 --rings 3 --fields 3 --quiet \
  -o @OUT@/o.toml
check tolerance exact tolerance lenses/doublet.toml --trials 20 --rings 3 --fields 3 \
  --no-sensitivity --quiet --csv @OUT@/t.csv --histogram @OUT@/h.svg
check export export export lenses/singlet.toml -o @OUT@/ex --image-size 96x64
mkdir -p "$tmp/in"
for i in 0 1 2 3; do "$lensopt" chart -o "$tmp/in/c$i.png" --size "$((200 + 4 * i))x120" > /dev/null; done
check render render render lenses/cooke.toml "$tmp/in" -o @OUT@/r --jobs 1 -q
check search masked search lenses/doublet.toml --glass-seeds 2 --rings 3 --fields 3 \
  --max-iterations 2 --max-rounds 1 --top 2 -q --jobs 1 -o @OUT@/s
[ "$journal_seen" -gt 0 ] || fail "no failed render left its journal: the resume was not tested"
echo "ok"
