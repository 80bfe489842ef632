#!/usr/bin/env bash
# CI: the SLURM path of the sweeps, for real, on a one-node cluster started here.
#
#   .ci/slurm_sweep.sh [FAUST_DIR]      (default ../shared/data/faust_reg; called by .ci/run)
#
# 1. installs slurm-wlm and munge with apt-get when they are absent (no apt-get/dpkg, or
#    not root: says so and skips this check, exit 0);
# 2. starts munged, slurmctld and slurmd directly (no systemd), with a slurm.conf, key,
#    sockets, state and logs in a temporary folder (one node, proctrack/linuxproc,
#    task/none, select/cons_tres, no accounting: sacct does not work, as on clusters
#    without slurmdbd) and ports of their own, so an existing SLURM is not touched;
# 3. runs a three-point sweep (sshade.n_low=300,500,800) on two FAUST cases through
#    hydra/launcher=slurm, kills job 2's Python process (kill -9) while it runs, and checks
#    that the sweep command exits 0 with a table of 2 done + 1 killed;
# 4. resumes the sweep (python -m eval.sweeps resume DIR) and checks 3 done, the killed job
#    alone re-submitted;
# 5. stops the daemons it started, by PID (trap on exit), and removes the folder.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
REPO=$(pwd)
FAUST=$(realpath -m "${1:-../shared/data/faust_reg}")
T0=$(date +%s)
say() { echo "slurm-ci [$(( $(date +%s) - T0 ))s]: $*"; }

if [ ! -f "$FAUST/tr_reg_000.ply" ]; then
  say "$FAUST not found; skipping the SLURM sweep check"
  exit 0
fi

# ---- 1. packages
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null \
   || ! command -v sbatch >/dev/null; then
  if ! command -v apt-get >/dev/null || ! command -v dpkg >/dev/null; then
    say "slurm-wlm/munge are not installed and apt-get/dpkg are not available: SKIPPING the SLURM sweep check"
    exit 0
  fi
  if [ "$(id -u)" -ne 0 ]; then
    say "slurm-wlm/munge are not installed and this is not root (apt-get needs it): SKIPPING the SLURM sweep check"
    exit 0
  fi
  say "installing slurm-wlm and munge (apt-get)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q >/dev/null
  apt-get install -y -q --no-install-recommends slurm-wlm munge >/dev/null
fi
if [ "$(id -u)" -ne 0 ]; then
  say "slurmd must run as root (it starts jobs as their user): SKIPPING the SLURM sweep check"
  exit 0
fi
say "$(slurmctld -V), $(munged -V 2>&1 | head -1)"

# ---- 2. a one-node cluster in a temporary folder
T=$(mktemp -d /tmp/sshade-slurm-ci.XXXXXX)
chmod 700 "$T"
PIDS=()
cleanup() {
  rc=$?
  if command -v squeue >/dev/null && [ -n "${SLURM_CONF:-}" ]; then
    ids=$(squeue -h -o %A 2>/dev/null | sort -u || true)
    [ -n "$ids" ] && scancel $ids 2>/dev/null || true
  fi
  for (( i=${#PIDS[@]}-1; i>=0; i-- )); do
    kill "${PIDS[$i]}" 2>/dev/null || true
  done
  for p in "${PIDS[@]}"; do
    for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$p" 2>/dev/null || true
  done
  if [ "$rc" -ne 0 ]; then
    for f in "$T"/slurmctld.log "$T"/slurmd.log "$T"/munge/munged.log "$T"/sweep.log "$T"/resume.log; do
      [ -f "$f" ] && { echo "---- $f (last 40 lines)"; tail -40 "$f"; }
    done
    echo "slurm-ci: FAILED (rc $rc) after $(( $(date +%s) - T0 ))s"
  fi
  rm -rf "$T"
  exit "$rc"
}
trap cleanup EXIT

free_port() { python - <<'EOF'
import socket
s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()
EOF
}

mkdir -p "$T/munge" "$T/state" "$T/spool"
chmod 700 "$T/munge"
dd if=/dev/urandom of="$T/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$T/munge/munge.key"
SOCK="$T/munge/munge.socket"
munged --foreground --force --key-file="$T/munge/munge.key" --socket="$SOCK" \
  --pid-file="$T/munge/munged.pid" --log-file="$T/munge/munged.log" --seed-file="$T/munge/munged.seed" \
  > "$T/munge/munged.out" 2>&1 &
PIDS+=($!)
for _ in $(seq 50); do [ -S "$SOCK" ] && break; sleep 0.1; done
[ -S "$SOCK" ] || { say "munged did not start"; exit 1; }

NODE=$(hostname -s)
CPUS=$(nproc)
MEM_MB=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 * 8 / 10 ))
cat > "$T/slurm.conf" <<EOF
ClusterName=sshadeci
SlurmctldHost=$NODE(127.0.0.1)
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
AuthType=auth/munge
AuthInfo=socket=$SOCK
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$T/state
SlurmdSpoolDir=$T/spool
SlurmctldPidFile=$T/slurmctld.pid
SlurmdPidFile=$T/slurmd.pid
SlurmctldLogFile=$T/slurmctld.log
SlurmdLogFile=$T/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerType=sched/builtin
MpiDefault=none
ReturnToService=2
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$CPUS RealMemory=$MEM_MB State=UNKNOWN
PartitionName=debug Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$T/slurm.conf"
slurmctld -D -c -f "$SLURM_CONF" > "$T/slurmctld.out" 2>&1 &
PIDS+=($!)
slurmd -D -f "$SLURM_CONF" > "$T/slurmd.out" 2>&1 &
PIDS+=($!)
for _ in $(seq 120); do
  state=$(sinfo -h -o %T 2>/dev/null | head -1 || true)
  [ "$state" = "idle" ] && break
  sleep 0.5
done
[ "${state:-}" = "idle" ] || { say "the node did not become idle (state '${state:-}')"; exit 1; }
say "one-node cluster up: node $NODE, $CPUS CPUs, partition debug (daemons ${PIDS[*]})"
if sacct -n >/dev/null 2>&1; then say "note: sacct works here"; else say "sacct does not work (no accounting), as intended"; fi

# ---- 3. the sweep, with job 2 killed while it runs
export PYTHONPATH="$REPO${PYTHONPATH:+:$PYTHONPATH}"
SW="$T/sweep"
ARGS=(-m dataset=faust "dataset.root=$FAUST" dataset.limit=2 "methods=[SShaDe]" sshade.n_low=300,500,800
      sshade.n_samplings=2 sshade.workers=1 hydra/launcher=slurm hydra.launcher.partition=debug
      hydra.launcher.cpus_per_task=1 hydra.launcher.mem_gb=1 hydra.launcher.timeout_min=10
      hydra.launcher.poll_s=1 "hydra.sweep.dir=$SW")
say "sweep: python -m eval.sweeps ${ARGS[*]}"
python -m eval.sweeps "${ARGS[@]}" > "$T/sweep.log" 2>&1 &
SWEEP=$!
KILLED=""
for _ in $(seq 1500); do   # up to 150 s for job 2 to start
  if [ -f "$SW/2/status.json" ]; then
    KILLED=$(python -c "import json,sys; s=json.load(open(sys.argv[1])); print(s['pid'] if s['status']=='running' else '')" \
             "$SW/2/status.json" 2>/dev/null || true)
    [ -n "$KILLED" ] && break
  fi
  kill -0 "$SWEEP" 2>/dev/null || break
  sleep 0.1
done
[ -n "$KILLED" ] || { say "job 2 never ran"; exit 1; }
kill -9 "$KILLED"
say "job 2 running (python pid $KILLED): killed with kill -9"
rc=0
wait "$SWEEP" || rc=$?
tail -25 "$T/sweep.log"
[ "$rc" -eq 0 ] || { say "the sweep command exited with $rc, expected 0"; exit 1; }
check() {  # check DIR EXPECTED_STATUSES (comma-separated, by job number)
  python - "$1" "$2" <<'EOF'
import sys
import pandas as pd
d, want = sys.argv[1], sys.argv[2].split(",")
df = pd.read_csv(f"{d}/sweep_table.csv", keep_default_na=False).sort_values("job")
got = list(df["status"])
print("slurm-ci: table:", ", ".join(f"job {j} (n_low {n}) {s}" for j, n, s in zip(df["job"], df["sshade.n_low"], got)))
if got != want:
    sys.exit(f"slurm-ci: expected {want}, got {got}")
EOF
}
check "$SW" done,done,killed
say "sweep with a killed job: exit 0, table 2 done + 1 killed: OK"

# ---- 4. resume
rc=0
python -m eval.sweeps resume "$SW" > "$T/resume.log" 2>&1 || rc=$?
grep -E "^resume:|submitted|not submitted|### Sweep" "$T/resume.log" || true
[ "$rc" -eq 0 ] || { say "resume exited with $rc"; exit 1; }
grep -q "submitted 1 job(s)" "$T/resume.log" || { say "resume did not submit exactly the killed job"; exit 1; }
check "$SW" done,done,done
say "resume: only job 2 re-submitted, table 3 done: OK"
say "PASSED in $(( $(date +%s) - T0 ))s"
