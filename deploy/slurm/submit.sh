#!/usr/bin/env bash
# Spreads a sysid study over a Slurm cluster: a job array of SHARDS tasks (study.sbatch), then
# a merge job (merge.sbatch) that runs when every task has ended, however it ended.
#
#   deploy/slurm/submit.sh [--cpus N] [--tasks LIST] SHARDS OUT STUDY-ARGS...
#   deploy/slurm/submit.sh 16 /scratch/vdp-study --system van-der-pol --trials 100000 --perturb 0.3
#
# The result is OUT/merged (study.json, trials.jsonl, summary.json, summary.md), the same as
# `sysid study STUDY-ARGS... --out OUT/merged` on one machine. Logs go to OUT/logs.
#
#   --cpus N      cores (rayon threads) per task; default: the smallest node of the partition,
#                 at most 4 (1 if sinfo cannot tell)
#   --tasks LIST  submit only these tasks (Slurm's array syntax: 3,7 or 2-5), as the merge
#                 job's message prints when shards failed; the shard count stays SHARDS
#
# Running the same command again continues: every task resumes its shard (finished shards end
# at once) and the merge rewrites the same result.
#
# Extra sbatch options: $SBATCH_ARRAY_OPTS for the array (account, partition, --time,
# --mem-per-cpu), $SBATCH_MERGE_OPTS for the merge job (account, partition). The binary:
# $SYSID if set, else `sysid` on PATH. The workspace builds for the CPU of the machine that
# builds (.cargo/config.toml); where the compute nodes are older than the login node, build
# the portable binary: RUSTFLAGS="-C target-cpu=x86-64" cargo install --path crates/cli
set -euo pipefail

usage() {
    echo "usage: $0 [--cpus N] [--tasks LIST] SHARDS OUT STUDY-ARGS...   (SHARDS a positive integer)" >&2
    exit 2
}

cpus=""
tasks=""
while [[ $# -gt 0 ]]; do
    case $1 in
        --cpus)
            [[ $# -ge 2 && $2 =~ ^[1-9][0-9]*$ ]] || usage
            cpus=$2
            shift 2
            ;;
        --tasks)
            [[ $# -ge 2 && $2 =~ ^[0-9,-]+$ ]] || usage
            tasks=$2
            shift 2
            ;;
        *) break ;;
    esac
done
if [[ $# -lt 3 || ! $1 =~ ^[1-9][0-9]*$ ]]; then
    usage
fi
shards=$1
out=$(mkdir -p "$2" && cd "$2" && pwd)
shift 2
here=$(cd "$(dirname "$0")" && pwd)
sysid=${SYSID:-$(command -v sysid || true)}
if [[ -z $sysid ]]; then
    echo "$0: no sysid on PATH: install it (cargo install --path crates/cli) or set SYSID" >&2
    exit 2
fi

# Cores per task: what the partition's smallest node offers, at most 4.
if [[ -z $cpus ]]; then
    partition=""
    for opt in ${SBATCH_ARRAY_OPTS:-}; do
        case $opt in --partition=* | -p=*) partition=${opt#*=} ;; esac
    done
    offered=$(sinfo -h ${partition:+--partition="$partition"} -o '%c' 2>/dev/null | sort -n | head -n 1 || true)
    offered=${offered%+}
    if [[ $offered =~ ^[0-9]+$ && $offered -ge 1 ]]; then
        cpus=$((offered < 4 ? offered : 4))
    else
        cpus=1
    fi
fi

mkdir -p "$out/logs"
# The batch scripts run from Slurm's spool, so every path they need is given to them.
export SYSID=$sysid SYSID_SUBMIT="$here/submit.sh"
# shellcheck disable=SC2086 # SBATCH_ARRAY_OPTS is a list of options
array=$(sbatch --parsable --export=ALL --cpus-per-task="$cpus" \
    --output="$out/logs/shard-%a.log" --open-mode=append --signal=B:USR1@120 \
    ${SBATCH_ARRAY_OPTS:-} --array="${tasks:-1-$shards}" \
    "$here/study.sbatch" "$out" "$shards" "$@")
array=${array%%;*}
# afterany: the merge runs however the tasks end, and says what is missing if any failed.
# shellcheck disable=SC2086 # SBATCH_MERGE_OPTS is a list of options
merge=$(sbatch --parsable --export=ALL --dependency="afterany:$array" --kill-on-invalid-dep=yes \
    --output="$out/logs/merge-%j.log" ${SBATCH_MERGE_OPTS:-} \
    "$here/merge.sbatch" "$out" "$shards" "$@")
merge=${merge%%;*}
echo "study array $array (tasks ${tasks:-1-$shards} of $shards, $cpus cores each), merge $merge"
echo "results in $out/merged, logs in $out/logs; progress: $sysid merge --check $out/shard-*"
