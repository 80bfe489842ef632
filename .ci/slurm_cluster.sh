# Sourced by the SLURM checks of CI (.ci/slurm_sweep.sh, .ci/slurm_table.sh): a one-node
# SLURM started for the occasion, stopped and removed when the caller exits.
#
# The caller sets CHECK (its name in messages), REPO and the function say, and may list
# in LOGS the files whose tail it wants printed on failure. This file
# 1. installs slurm-wlm and munge with apt-get when they are absent (no apt-get/dpkg, or
#    not root: says so and skips the caller's check, exit 0);
# 2. starts munged, slurmctld and slurmd directly (no systemd), with a slurm.conf, key,
#    sockets, state and logs in a temporary folder $T (one node, proctrack/linuxproc,
#    task/none, select/cons_tres, no accounting: sacct does not work, as on clusters
#    without slurmdbd) and ports of their own, so an existing SLURM is not touched;
#    exports SLURM_CONF;
# 3. defines array_task_pid FOLDER TASK: the PID of the Python process of array task TASK
#    (SLURM_ARRAY_TASK_ID) whose submitit folder lies under FOLDER, empty when none runs; and
#    array_task_when FOLDER TASK RUN CMD...: that PID once the command CMD succeeds and the
#    task runs (polled every 0.1 s, up to 300 s, while process RUN lives; empty: never);
# 4. on exit (trap): cancels the jobs left, stops the daemons it started, by PID, prints
#    the logs' tails on failure and removes $T.

# ---- 1. packages
if ! command -v slurmctld >/dev/null || ! command -v slurmd >/dev/null || ! command -v munged >/dev/null \
   || ! command -v sbatch >/dev/null; then
  if ! command -v apt-get >/dev/null || ! command -v dpkg >/dev/null; then
    say "slurm-wlm/munge are not installed and apt-get/dpkg are not available: SKIPPING $CHECK"
    exit 0
  fi
  if [ "$(id -u)" -ne 0 ]; then
    say "slurm-wlm/munge are not installed and this is not root (apt-get needs it): SKIPPING $CHECK"
    exit 0
  fi
  say "installing slurm-wlm and munge (apt-get)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q >/dev/null
  apt-get install -y -q --no-install-recommends slurm-wlm munge >/dev/null
fi
if [ "$(id -u)" -ne 0 ]; then
  say "slurmd must run as root (it starts jobs as their user): SKIPPING $CHECK"
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
    for f in "$T"/slurmctld.log "$T"/slurmd.log "$T"/munge/munged.log ${LOGS[@]+"${LOGS[@]}"}; do
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


array_task_pid() {
  local pid
  for pid in $(pgrep -f "^[^ ]*python[^ ]* -u -m submitit.core._submit $1/" || true); do
    if tr '\0' '\n' < "/proc/$pid/environ" 2>/dev/null | grep -qx "SLURM_ARRAY_TASK_ID=$2"; then
      echo "$pid"
      return
    fi
  done
}

array_task_when() {
  local folder=$1 task=$2 run=$3 pid
  shift 3
  for _ in $(seq 3000); do
    if "$@"; then
      pid=$(array_task_pid "$folder" "$task")
      [ -n "$pid" ] && { echo "$pid"; return; }
    fi
    kill -0 "$run" 2>/dev/null || return 0
    sleep 0.1
  done
}
