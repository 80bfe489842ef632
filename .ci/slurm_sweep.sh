#!/usr/bin/env bash
# CI: the SLURM path of the sweeps, for real, on a one-node cluster started here.
#
#   .ci/slurm_sweep.sh [FAUST_DIR]      (default ../shared/data/faust_reg; called by .ci/run)
#
# 1-2. starts a one-node SLURM in a temporary folder (.ci/slurm_cluster.sh: installs
#    slurm-wlm and munge with apt-get when absent, or skips this check, exit 0);
# 3. runs a three-point sweep (sshade.n_low=300,500,800) on two FAUST cases through
#    hydra/launcher=slurm, kills job 2's Python process (kill -9) while it runs, and checks
#    that the sweep command exits 0 with a table of 2 done + 1 killed;
# 4. resumes the sweep (python -m eval.sweeps resume DIR) and checks 3 done, the killed job
#    alone re-submitted;
# 5. stops the daemons it started, by PID (trap on exit), and removes the folder
#    (.ci/slurm_cluster.sh).
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

CHECK="the SLURM sweep check"
LOGS=()
# shellcheck source=.ci/slurm_cluster.sh
source .ci/slurm_cluster.sh
LOGS=("$T/sweep.log" "$T/resume.log")

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
