#!/usr/bin/env bash
# Option names are consistent across commands: --threads wherever a command has threads,
# -q/--quiet wherever it prints progress, --no-relative-illumination for render; the old names
# (--jobs, --no-ri) still work as aliases.
set -euo pipefail
lensopt="$1"
fail() { echo "FAIL: $*" >&2; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for cmd in analyze plot optimize render tolerance export bench search; do
  "$lensopt" "$cmd" --help > "$tmp/$cmd.txt" || fail "$cmd --help"
  grep -q -- "--threads" "$tmp/$cmd.txt" || fail "$cmd has no --threads"
done
for cmd in optimize render tolerance search; do
  grep -q -- "-q,--quiet" "$tmp/$cmd.txt" || fail "$cmd has no -q,--quiet"
done
grep -q -- "--no-relative-illumination" "$tmp/render.txt" ||
  fail "render has no --no-relative-illumination"
grep -q -- "--no-relative-illumination" "$tmp/optimize.txt" ||
  fail "optimize (--joint) has no --no-relative-illumination"
# Old names parse (the help of an alias-taking command accepts them without an error).
"$lensopt" tolerance lenses/doublet.toml --jobs 1 --trials 2 --rings 2 --fields 2 \
  --no-sensitivity -q > /dev/null || fail "tolerance --jobs (alias)"
"$lensopt" tolerance lenses/doublet.toml --threads 1 --trials 2 --rings 2 --fields 2 \
  --no-sensitivity --quiet > /dev/null || fail "tolerance --threads"
# OpenMP threads wait passively unless the user says otherwise (core/passive_threads.h): the
# spin count libgomp finally runs with is 0, and a user's OMP_WAIT_POLICY is kept.
spin() { OMP_DISPLAY_ENV=verbose "$@" --version 2>&1 >/dev/null | sed -n "s/.*GOMP_SPINCOUNT = '\(.*\)'/\1/p" | tail -1; }
[ "$(env -u OMP_WAIT_POLICY bash -c "$(declare -f spin); spin '$lensopt'")" = 0 ] ||
  fail "OpenMP threads spin by default"
[ "$(OMP_WAIT_POLICY=active bash -c "$(declare -f spin); spin '$lensopt'")" != 0 ] ||
  fail "the user's OMP_WAIT_POLICY=active is not kept"
# Out-of-range counts and non-finite numbers are refused by name before any work (-1, 0, a
# negative number or nan used to be taken silently as "not given" and the default run).
out_of_range() {
  local status=0
  "$lensopt" "$@" > "$tmp/range.out" 2> "$tmp/range.err" || status=$?
  [ "$status" -ne 0 ] && grep -q -- "$3" "$tmp/range.err" ||
    fail "$* was accepted (exit $status): $(cat "$tmp/range.err")"
  [ ! -e "$tmp/o.toml" ] || fail "$* wrote a lens"
}
for bad in "--threads -1" "--rings 0" "--fields -3" "--max-iterations -5" "--neighbours -2" \
  "--adam-steps 0" "--min-glass-mm nan" "--weight-glass nan" "--max-ray-angle-deg inf"; do
  # shellcheck disable=SC2086
  out_of_range optimize lenses/doublet.toml $bad -o "$tmp/o.toml" -q
done
for bad in "--threads -1" "--jobs -1" "--rings 0" "--fields 0" "--max-iterations -5" \
  "--max-rounds 0" "--glass-seeds 0" "--top -1" "--neighbours -1" "--f-number nan" \
  "--half-field-deg nan" "--focal-length-mm inf"; do
  # shellcheck disable=SC2086
  out_of_range search lenses/doublet.toml $bad -o "$tmp/s" -q --list
done
echo "PASS"
