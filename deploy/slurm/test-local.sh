#!/usr/bin/env bash
# The Slurm deployment on a real Slurm: brings up a single-node cluster (munged, slurmctld and
# slurmd from Debian's slurm-wlm and munge packages, configured in a temporary directory,
# nothing in /etc changed), then, as a user following the README:
#   1. runs a sharded study through submit.sh with its defaults and checks that the merged
#      result equals the unsharded study (every field but the measured times);
#   2. makes one shard fail and checks that the merge job ends with a message naming it and
#      the command that resubmits it, then runs that command and checks the study completes;
#   3. runs the first command again and checks it continues (the merge succeeds again).
# Tears down what it started. Needs root (the daemons run as root here) and the packages:
#   apt-get install slurm-wlm munge
# Usage: deploy/slurm/test-local.sh [SYSID]   (default: target/debug/sysid, else sysid on PATH)
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
sysid=${1:-$root/target/debug/sysid}
[[ -x $sysid ]] || sysid=$(command -v sysid)
sysid=$(cd "$(dirname "$sysid")" && pwd)/$(basename "$sysid")
for tool in munged slurmctld slurmd sbatch sinfo squeue; do
    command -v "$tool" >/dev/null || {
        echo "test-local: $tool missing: apt-get install slurm-wlm munge" >&2
        exit 2
    }
done

tmp=$(mktemp -d /tmp/sysid-slurm.XXXXXX)
pids=()
teardown() {
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
    sleep 1
    for pid in "${pids[@]}"; do kill -9 "$pid" 2>/dev/null || true; done
    [[ -n ${KEEP:-} ]] || rm -rf "$tmp"
}
trap teardown EXIT
fail() {
    echo "test-local: FAILED: $*" >&2
    for log in "$tmp"/slurmctld.log "$tmp"/slurmd.log; do
        echo "--- $log" >&2
        tail -n 20 "$log" >&2 || true
    done
    exit 1
}

# --- A single-node cluster in $tmp -------------------------------------------------------
host=$(hostname -s)
cpus=$(nproc)
memory=$(($(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 / 2))
mkdir -p "$tmp/munge" "$tmp/state" "$tmp/spool"
dd if=/dev/urandom of="$tmp/munge/key" bs=1024 count=1 status=none
chmod 400 "$tmp/munge/key"
chmod 711 "$tmp/munge"
munged --force --foreground --key-file="$tmp/munge/key" --socket="$tmp/munge/socket" \
    --pid-file="$tmp/munge/pid" --log-file="$tmp/munge/log" --seed-file="$tmp/munge/seed" \
    >"$tmp/munged.out" 2>&1 &
pids+=($!)
port=$((17000 + RANDOM % 2000))
cat >"$tmp/slurm.conf" <<EOF
ClusterName=sysidtest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$tmp/munge/socket
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/slurmctld.pid
SlurmdPidFile=$tmp/slurmd.pid
SlurmctldLogFile=$tmp/slurmctld.log
SlurmdLogFile=$tmp/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/backfill
ReturnToService=2
MpiDefault=none
MailProg=/bin/true
SlurmdTimeout=30
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$tmp/slurm.conf
for ((i = 0; i < 50; i++)); do [[ -S $tmp/munge/socket ]] && break; sleep 0.1; done
slurmctld -D -i >"$tmp/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D >"$tmp/slurmd.out" 2>&1 &
pids+=($!)
for ((i = 0; i < 60; i++)); do
    state=$(sinfo -h -o '%t' 2>/dev/null || true)
    [[ $state == idle ]] && break
    sleep 0.5
done
[[ $state == idle ]] || fail "the node did not come up (state '$state')"
echo "test-local: single-node Slurm up ($host, $cpus CPUs)"

# Waits for job $1 to leave the queue; prints its final state.
finish() {
    for ((i = 0; i < 240; i++)); do
        if [[ -z $(squeue -h -j "$1" 2>/dev/null) ]]; then
            scontrol show job "$1" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' | head -n 1
            return
        fi
        sleep 0.5
    done
    fail "job $1 still queued after 2 minutes: $(squeue -j "$1")"
}

# trials.jsonl and summary.json without measured times.
untimed() {
    python3 - "$1" <<'EOF'
import json, sys
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if k != "time_ms"}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v
d = sys.argv[1]
print(json.dumps([strip(json.loads(l)) for l in open(d + "/trials.jsonl")]))
print(json.dumps(strip(json.load(open(d + "/summary.json")))))
EOF
}

study=(--system falling-body --trials 24 --perturb 0.3 --methods "goodman,gauss-newton-ls")
submit() { SYSID=$sysid "$here/submit.sh" "$@"; }
job_of() { sed -n 's/.*merge \([0-9]*\).*/\1/p' <<<"$1"; }

# --- 1. Sharded = unsharded ---------------------------------------------------------------
"$sysid" study "${study[@]}" --out "$tmp/whole" >/dev/null 2>&1 || fail "the unsharded study"
said=$(submit 4 "$tmp/run" "${study[@]}") || fail "submit.sh: $said"
echo "$said"
state=$(finish "$(job_of "$said")")
[[ $state == COMPLETED ]] || fail "merge job $state: $(cat "$tmp"/run/logs/merge-*.log)"
[[ $(untimed "$tmp/run/merged") == "$(untimed "$tmp/whole")" ]] ||
    fail "the merged study differs from the unsharded one"
grep -q "| goodman |" "$tmp"/run/logs/merge-*.log || fail "no summary table in the merge log"
ls "$tmp"/run/logs/shard-1.log >/dev/null || fail "no task log under OUT/logs"
echo "test-local: 4 shards merged into exactly the unsharded study"

# --- 2. A failing shard: the merge says which and how to resubmit -------------------------
cat >"$tmp/flaky" <<EOF
#!/usr/bin/env bash
# sysid, except that shard 2 fails.
[[ \${SLURM_ARRAY_TASK_ID:-} == 2 && \$1 == study ]] && { echo "injected failure" >&2; exit 3; }
exec "$sysid" "\$@"
EOF
chmod +x "$tmp/flaky"
said=$(SYSID=$tmp/flaky "$here/submit.sh" 4 "$tmp/flaky-run" "${study[@]}") || fail "submit.sh: $said"
merge=$(job_of "$said")
state=$(finish "$merge")
log=$tmp/flaky-run/logs/merge-$merge.log
[[ $state == FAILED ]] || fail "the merge job after a failed shard ended $state, not FAILED"
grep -q "shards 2 of 4 are missing or incomplete" "$log" || fail "no clear message: $(cat "$log")"
resubmit=$(grep -A1 "Resubmit exactly those" "$log" | tail -n 1)
[[ $resubmit == *"--tasks 2 4 "* ]] || fail "no resubmit command: $(cat "$log")"
echo "test-local: the merge job named the failed shard: $resubmit"
said=$(SYSID=$sysid eval "$resubmit") || fail "the resubmit command: $said"
state=$(finish "$(job_of "$said")")
[[ $state == COMPLETED ]] || fail "merge after resubmitting ended $state"
[[ $(untimed "$tmp/flaky-run/merged") == "$(untimed "$tmp/whole")" ]] ||
    fail "the study completed by resubmission differs from the unsharded one"
echo "test-local: resubmitting the failed shard completed the study"

# --- 3. The same command again continues ---------------------------------------------------
said=$(submit 4 "$tmp/run" "${study[@]}") || fail "submit.sh again: $said"
state=$(finish "$(job_of "$said")")
[[ $state == COMPLETED ]] || fail "running the same command again: merge $state"
[[ $(untimed "$tmp/run/merged") == "$(untimed "$tmp/whole")" ]] || fail "the second run changed the result"
echo "test-local: running the same command again continued and merged the same result"

# --- 4. Near the time limit a task stops, keeps its trials and requeues itself -------------
# Slurm's warning signal (USR1, --signal=B:USR1@120 from submit.sh), sent early by hand.
long=(--system van-der-pol --trials 300 --perturb 0.3 --methods goodman)
said=$(submit 1 "$tmp/long" "${long[@]}") || fail "submit.sh: $said"
array=$(sed -n 's/^study array \([0-9]*\).*/\1/p' <<<"$said")
for ((i = 0; i < 100; i++)); do
    [[ -s $tmp/long/shard-0001/trials.jsonl ]] && break
    sleep 0.2
done
scancel --batch --signal=USR1 "${array}_1"
# Slurm holds a requeued job for two minutes (its BeginTime); let it start again now.
for ((i = 0; i < 100; i++)); do
    [[ $(squeue -h -j "${array}_1" -o '%t %r' 2>/dev/null) == "PD BeginTime" ]] && break
    sleep 0.2
done
scontrol update JobId="${array}_1" StartTime=now
state=$(finish "$(job_of "$said")")
[[ $state == COMPLETED ]] || fail "merge after a requeue ended $state: $(cat "$tmp"/long/logs/*.log)"
grep -q "time limit near: stopping shard 1" "$tmp/long/logs/shard-1.log" ||
    fail "the task did not stop on USR1: $(cat "$tmp/long/logs/shard-1.log")"
[[ $(grep -c '"method":"goodman"' "$tmp/long/merged/trials.jsonl") == 300 ]] ||
    fail "the requeued study lost or repeated trials"
echo "test-local: a task told its time is up stopped, requeued itself and the study completed"
echo "test-local: ok"
