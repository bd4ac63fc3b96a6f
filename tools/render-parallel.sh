#!/usr/bin/env bash
# Renders a dataset as SHARDS independent `lensopt render --shard I/SHARDS` runs with GNU parallel,
# all into one output folder, then joins their metrics.
#
#   tools/render-parallel.sh LENS OUTDIR SHARDS INPUT... [lensopt render flags...]
#
# GNU parallel keeps JOBS shards running (default: every core, each shard one thread), on this
# machine or, with PARALLEL_ARGS="--sshloginfile hosts.txt --workdir $PWD", on machines that share
# the file system (each needs the binary, the lens and the inputs at the same paths). A shard
# writes OUTDIR/render_metrics-shardIofN.csv/.json; rerunning the command resumes every shard
# where it stopped; `lensopt render merge OUTDIR` then writes OUTDIR/render_metrics.csv/.json,
# as one run over the dataset writes them.
#
# Environment: LENSOPT (default build/lensopt), JOBS (shards at once), PARALLEL_ARGS.
set -euo pipefail
if [ $# -lt 4 ]; then
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
lens=$1 out=$2 shards=$3
shift 3
command -v parallel > /dev/null || { echo "GNU parallel not found (apt-get install parallel)" >&2; exit 1; }
lensopt=$(realpath "${LENSOPT:-build/lensopt}")
# --halt never: a failed shard does not stop the others (rerun to resume it).
# shellcheck disable=SC2086
parallel --jobs "${JOBS:-$(nproc)}" --halt never --line-buffer --tagstring 'shard {}' \
  ${PARALLEL_ARGS:-} "$lensopt" render "$lens" "$@" -o "$out" --shard "{}/$shards" --threads 1 -q \
  ::: $(seq 1 "$shards") || echo "some shards did not finish; rerun to resume them" >&2
"$lensopt" render merge "$out"
