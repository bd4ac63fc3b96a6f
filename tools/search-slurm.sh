#!/usr/bin/env bash
# Runs a `lensopt search` as a Slurm job array, one shard per array task, then merges the shards.
#
#   tools/search-slurm.sh DESCRIPTION.toml OUTDIR SHARDS [lensopt search flags...]
#
# submits (sbatch) an array of SHARDS tasks, task I running
#   lensopt search DESCRIPTION.toml --shard I/SHARDS -o OUTDIR/shard-I-of-SHARDS --jobs $SLURM_CPUS_PER_TASK
# and a merge job that waits for the array (afterany) and writes OUTDIR/merged/ (leaderboard.csv,
# leaderboard.json, best/). Every shard writes one result file per finished candidate, so a task
# that hits its time limit (Slurm sends SIGTERM; lensopt stops taking candidates) or is requeued
# resumes where it stopped when it runs again: resubmit the same command, or `sbatch --requeue`.
# Run the merge by hand at any time for a partial leaderboard:
#   lensopt search merge OUTDIR/shard-* -o OUTDIR/merged
#
# Environment: LENSOPT (the binary; default build/lensopt, made absolute), SBATCH_ARGS (extra sbatch
# options, e.g. "--partition=cpu --time=04:00:00"), CPUS (cores per task, default 4).
# The description's lens paths are relative to the description; the folders must be on a file
# system every node sees.
set -euo pipefail

if [ -n "${SLURM_ARRAY_TASK_ID:-}" ]; then
  # One array task: shard I of N (1-based, whatever the array's first index is).
  desc=$1 out=$2 shards=$3
  shift 3
  i=$((SLURM_ARRAY_TASK_ID - ${SLURM_ARRAY_TASK_MIN:-1} + 1))
  exec "$LENSOPT" search "$desc" --shard "$i/$shards" -o "$out/shard-$i-of-$shards" \
    --jobs "${SLURM_CPUS_PER_TASK:-1}" -q "$@"
fi

if [ $# -lt 3 ]; then
  sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
desc=$(realpath "$1") out=$(realpath -m "$2") shards=$3
shift 3
command -v sbatch > /dev/null || { echo "sbatch not found: this script needs Slurm" >&2; exit 1; }
export LENSOPT=$(realpath "${LENSOPT:-build/lensopt}")
cpus=${CPUS:-4}
mkdir -p "$out/logs"
# shellcheck disable=SC2086
array=$(sbatch --parsable --job-name=lensopt-search --array="1-$shards" --cpus-per-task="$cpus" \
  --output="$out/logs/shard-%a.log" --export=ALL ${SBATCH_ARGS:-} "$0" "$desc" "$out" "$shards" "$@")
shard_dirs=""
for i in $(seq 1 "$shards"); do shard_dirs+=" $out/shard-$i-of-$shards"; done
# shellcheck disable=SC2086
merge=$(sbatch --parsable --job-name=lensopt-search-merge --dependency="afterany:$array" \
  --cpus-per-task=1 --output="$out/logs/merge.log" ${SBATCH_ARGS:-} \
  --wrap="'$LENSOPT' search merge $shard_dirs -o '$out/merged'")
echo "submitted array job $array ($shards shards) and merge job $merge; results in $out/merged/"
