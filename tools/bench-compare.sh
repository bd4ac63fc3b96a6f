#!/usr/bin/env bash
# Side-by-side timing of two lensopt executables in one run, alternating (BENCHMARKS.md):
#
#   tools/bench-compare.sh OLD_LENSOPT NEW_LENSOPT
#
# CPU seconds (user + sys, /usr/bin/time) of a 1280 x 720 render through the Doublet and of
# analyze on the Cooke and the double Gauss .zmx, three times each, then `lensopt bench` of each;
# prints the load average before and after (it matters on a shared machine).
set -uo pipefail
base="${1:?usage: tools/bench-compare.sh OLD_LENSOPT NEW_LENSOPT}"
new="${2:?usage: tools/bench-compare.sh OLD_LENSOPT NEW_LENSOPT}"
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$new" chart -o "$tmp/chart.png" --size 1280x720 > /dev/null
cpu() {
  /usr/bin/time -f "%U %S %e" "$@" > /dev/null 2> "$tmp/t"
  tail -1 "$tmp/t" | awk '{printf "%.2f cpu-s (%.2f wall)", $1 + $2, $3}'
}
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
for i in 1 2 3; do
  for b in base new; do
    bin=${!b}
    echo "$b render doublet 1280x720: $(cpu "$bin" render lenses/doublet.toml "$tmp/chart.png" -o "$tmp/r-$b" --force -q)"
    echo "$b analyze cooke: $(cpu "$bin" analyze lenses/cooke.toml)"
    echo "$b analyze double_gauss .zmx: $(cpu "$bin" analyze lenses/zmx/double_gauss_100.zmx)"
  done
done
for b in base new; do
  echo "== $b bench"
  "${!b}" bench 2>&1 | tail -4
done
echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
