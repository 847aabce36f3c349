#!/usr/bin/env bash
# Spreads a sysid study over a Slurm cluster: a job array of SHARDS tasks (study.sbatch), then
# a merge job (merge.sbatch) that starts only when every task has succeeded (afterok).
#
#   deploy/slurm/submit.sh SHARDS OUT STUDY-ARGS...
#   deploy/slurm/submit.sh 16 /scratch/vdp-study --system van-der-pol --trials 100000 --perturb 0.3
#
# The result is OUT/merged (trials.jsonl, summary.json, summary.md), the same as
# `sysid study STUDY-ARGS... --out OUT/merged` on one machine. Extra sbatch options (account,
# partition) go in $SBATCH_OPTS, for example SBATCH_OPTS="--account=abc --partition=short".
set -euo pipefail

if [[ $# -lt 3 || ! $1 =~ ^[1-9][0-9]*$ ]]; then
    echo "usage: $0 SHARDS OUT STUDY-ARGS...   (SHARDS a positive integer)" >&2
    exit 2
fi
shards=$1
out=$2
shift 2
here=$(cd "$(dirname "$0")" && pwd)
# shellcheck disable=SC2086 # SBATCH_OPTS is a list of options
array=$(sbatch --parsable ${SBATCH_OPTS:-} --array="1-$shards" "$here/study.sbatch" "$out" "$@")
array=${array%%;*}
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_OPTS:-} --dependency="afterok:$array" "$here/merge.sbatch" "$out")
merge=${merge%%;*}
echo "study array $array ($shards tasks), merge $merge: results in $out/merged"
