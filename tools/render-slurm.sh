#!/usr/bin/env bash
# Renders a dataset as a Slurm job array, one `lensopt render --shard I/SHARDS` per array task,
# all into one output folder, then joins the shards' metrics.
#
#   tools/render-slurm.sh LENS OUTDIR SHARDS INPUT... [lensopt render flags...]
#
# Task I runs `lensopt render LENS INPUT... -o OUTDIR --shard I/SHARDS --threads $SLURM_CPUS_PER_TASK`;
# a job that waits for the array (afterany) runs `lensopt render merge OUTDIR` (render_metrics.csv
# and .json for the whole dataset). A task that hits its time limit (Slurm sends SIGTERM: the
# shard finishes the images in flight and writes its metrics) or is killed resumes where it
# stopped when it runs again: resubmit the same command. The merge refuses while a shard is
# unfinished and names it. Paths must be on a file system every node sees.
#
# Environment: LENSOPT (default build/lensopt, made absolute), SBATCH_ARGS (extra sbatch options,
# e.g. "--partition=cpu --time=04:00:00"), CPUS (cores per task, default 4).
set -euo pipefail

if [ -n "${SLURM_ARRAY_TASK_ID:-}" ]; then
  lens=$1 out=$2 shards=$3
  shift 3
  i=$((SLURM_ARRAY_TASK_ID - ${SLURM_ARRAY_TASK_MIN:-1} + 1))
  exec "$LENSOPT" render "$lens" "$@" -o "$out" --shard "$i/$shards" \
    --threads "${SLURM_CPUS_PER_TASK:-1}" -q
fi

if [ $# -lt 4 ]; then
  sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
lens=$(realpath "$1") out=$(realpath -m "$2") shards=$3
shift 3
inputs=()
for a in "$@"; do  # inputs made absolute for the nodes; flags passed as they are
  if [ -e "$a" ]; then inputs+=("$(realpath "$a")"); else inputs+=("$a"); fi
done
command -v sbatch > /dev/null || { echo "sbatch not found: this script needs Slurm" >&2; exit 1; }
LENSOPT=$(realpath "${LENSOPT:-build/lensopt}")
export LENSOPT
mkdir -p "$out/logs"
# shellcheck disable=SC2086
array=$(sbatch --parsable --job-name=lensopt-render --array="1-$shards" --cpus-per-task="${CPUS:-4}" \
  --output="$out/logs/shard-%a.log" --export=ALL ${SBATCH_ARGS:-} "$0" "$lens" "$out" "$shards" \
  "${inputs[@]}")
# shellcheck disable=SC2086
merge=$(sbatch --parsable --job-name=lensopt-render-merge --dependency="afterany:$array" \
  --cpus-per-task=1 --output="$out/logs/merge.log" ${SBATCH_ARGS:-} \
  --wrap="'$LENSOPT' render merge '$out'")
echo "submitted array job $array ($shards shards) and merge job $merge; metrics in $out/render_metrics.csv"
