#!/usr/bin/env bash
# Runs a `lensopt search` as SHARDS independent shards with GNU parallel, then merges them.
#
#   tools/search-parallel.sh DESCRIPTION.toml OUTDIR SHARDS [lensopt search flags...]
#
# Shard I runs `lensopt search DESCRIPTION.toml --shard I/SHARDS -o OUTDIR/shard-I-of-SHARDS
# --jobs 1`; GNU parallel keeps JOBS of them running (default: every core), on this machine or,
# with PARALLEL_ARGS="--sshloginfile hosts.txt --workdir $PWD", on many machines sharing the file
# system (every host needs the binary and the lenses at the same paths). Rerunning the command
# resumes every shard where it stopped; the merge writes OUTDIR/merged/ (leaderboard.csv,
# leaderboard.json, best/), exactly the leaderboard of one `lensopt search` run.
#
# Environment: LENSOPT (default build/lensopt), JOBS (shards at once), PARALLEL_ARGS.
set -euo pipefail
if [ $# -lt 3 ]; then
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
desc=$1 out=$2 shards=$3
shift 3
command -v parallel > /dev/null || { echo "GNU parallel not found (apt-get install parallel)" >&2; exit 1; }
lensopt=$(realpath "${LENSOPT:-build/lensopt}")
jobs=${JOBS:-$(nproc)}
mkdir -p "$out"
# Each shard is one process with one optimizer thread; the shards run in parallel. --halt never:
# a failed shard does not stop the others (rerun to resume it).
# shellcheck disable=SC2086
parallel --jobs "$jobs" --halt never --line-buffer --tagstring 'shard {}' ${PARALLEL_ARGS:-} \
  "$lensopt" search "$desc" --shard "{}/$shards" -o "$out/shard-{}-of-$shards" --jobs 1 -q "$@" \
  ::: $(seq 1 "$shards") || echo "some shards did not finish; rerun to resume them" >&2
dirs=()
for i in $(seq 1 "$shards"); do
  [ -d "$out/shard-$i-of-$shards" ] && dirs+=("$out/shard-$i-of-$shards")
done
"$lensopt" search merge "${dirs[@]}" -o "$out/merged"
