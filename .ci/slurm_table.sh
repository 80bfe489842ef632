#!/usr/bin/env bash
# CI: a table's pairs as one SLURM job array (python -m eval ... cluster=slurm), for real,
# on a one-node cluster started here.
#
#   .ci/slurm_table.sh [FAUST_DIR]      (default ../shared/data/faust_reg; called by .ci/run)
#
# 1-2. starts a one-node SLURM in a temporary folder (.ci/slurm_cluster.sh: installs
#    slurm-wlm and munge with apt-get when absent, or skips this check, exit 0);
# 3. runs experiment=ci (2 FAUST cases) with ARAP, Elastic and SShaDe through the array
#    (one task per case), kills task 2's Python process (kill -9) once it has stored its
#    first pair, and checks that the command exits 0 with that task's other pairs as
#    error rows ("no record of this pair"), not stored, and every other row valid;
# 4. resumes it (resume=true) and checks that one task with exactly the killed pairs was
#    submitted and that the table has no error left;
# 5. runs the same config locally (jobs=1) and checks that cases.csv and table.csv agree
#    with the array's in every non-time column (benchmarks/table_change.py);
# 6. runs the array again without a kill and prints the wall times: local, array, and
#    the killed array and its resume.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
REPO=$(pwd)
FAUST=$(realpath -m "${1:-../shared/data/faust_reg}")
T0=$(date +%s)
say() { echo "slurm-table-ci [$(( $(date +%s) - T0 ))s]: $*"; }

if [ ! -f "$FAUST/tr_reg_000.ply" ]; then
  say "$FAUST not found; skipping the SLURM table check"
  exit 0
fi

CHECK="the SLURM table check"
LOGS=()
# shellcheck source=.ci/slurm_cluster.sh
source .ci/slurm_cluster.sh
LOGS=("$T/array.log" "$T/resume.log" "$T/local.log" "$T/clean.log")

export PYTHONPATH="$REPO${PYTHONPATH:+:$PYTHONPATH}"
ARR="$T/array"
# each run computes its references into a cache of its own (the cache is not part of a
# row's key), so that the times compare the same work
CONFIG=(experiment=ci "dataset.root=$FAUST" "methods=[ARAP,Elastic,SShaDe]" sshade.workers=1)
ARRAY=(cluster=slurm cluster.partition=debug cluster.cpus_per_task=1 cluster.mem_gb=1 cluster.timeout_min=20
       cluster.poll_s=1)

# ---- 3. the array, with task 2 killed after its first pair
say "array: python -m eval ${CONFIG[*]} ${ARRAY[*]} out_dir=$ARR"
t_array=$(date +%s.%N)
python -m eval "${CONFIG[@]}" "${ARRAY[@]}" "reference.cache=$T/refs_array" "out_dir=$ARR" > "$T/array.log" 2>&1 &
RUN=$!
# task 2's log (submitit's, in out_dir/slurm/) names its case in its first pair's line
task2_case() {
  sed -nE 's/^[0-9-]+ [0-9:,]+ INFO ([^ ]+) +[^ ]+ +[0-9.]+s +vol .*/\1/p' "$ARR"/slurm/*_1/*_log.err 2>/dev/null \
    | head -1 || true
}
stored_first_pair() { local c; c=$(task2_case); [ -n "$c" ] && ls "$ARR/runs/$c/"*.json >/dev/null 2>&1; }
KILLED=$(array_task_when "$ARR" 1 "$RUN" stored_first_pair)   # up to 300 s for task 2 to store its first pair
case2=$(task2_case)
[ -n "$KILLED" ] || { say "task 2 never stored a pair while running"; exit 1; }
kill -9 "$KILLED"
say "task 2 (case $case2, python pid $KILLED) stored $(ls "$ARR/runs/$case2" | tr '\n' ' ')and was killed with kill -9"
rc=0
wait "$RUN" || rc=$?
t_array=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_array")
grep -E "submitted|array task|have no record" "$T/array.log" || true
[ "$rc" -eq 0 ] || { say "the array command exited with $rc, expected 0"; exit 1; }
python - "$ARR" "$case2" <<'EOF'
import sys
from pathlib import Path
import pandas as pd
d, case = Path(sys.argv[1]), sys.argv[2]
df = pd.read_csv(d / "cases.csv", keep_default_na=False)
bad = df[df["error"] != ""]
print("slurm-table-ci: error rows:", "; ".join(f"{c} {m}: {e[:90]}" for c, m, e in zip(bad["case"], bad["method"], bad["error"])))
assert len(bad) >= 1 and set(bad["case"]) == {case}, "the error rows are not exactly the killed task's"
assert all("no record of this pair" in e for e in bad["error"]), "an error row does not say it has no record"
assert all(v == "" for v in bad["volume_err_pct"]), "an error row carries metrics"
assert not any((d / "runs" / case / f"{m}.json").exists() for m in bad["method"]), "a killed pair is stored"
assert len(df) == 6 and (df["error"] == "").sum() == 6 - len(bad)
print(f"slurm-table-ci: {len(bad)} pair(s) of {case} missing, {6 - len(bad)} rows valid")
EOF
N_MISSING=$(python -c "import pandas as pd,sys; print((pd.read_csv(sys.argv[1], keep_default_na=False)['error'] != '').sum())" "$ARR/cases.csv")
say "array with a killed task: exit 0, $N_MISSING pair(s) of $case2 reported missing: OK"

# ---- 4. resume
t_resume=$(date +%s.%N)
rc=0
python -m eval "${CONFIG[@]}" "${ARRAY[@]}" "reference.cache=$T/refs_array" "out_dir=$ARR" resume=true \
  > "$T/resume.log" 2>&1 || rc=$?
t_resume=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_resume")
grep -E "^resume:|submitted|array task" "$T/resume.log" || true
[ "$rc" -eq 0 ] || { say "resume exited with $rc"; exit 1; }
grep -q "resume: $(( 6 - N_MISSING )) run(s) restored" "$T/resume.log" \
  || { say "resume did not restore the $(( 6 - N_MISSING )) stored pairs"; exit 1; }
grep -q "submitted 1 array task(s)" "$T/resume.log" && grep -q "(case $case2, job .*): done; $N_MISSING pair(s) stored" \
  "$T/resume.log" || { say "resume did not submit exactly the killed pairs"; exit 1; }
say "resume: one task with the $N_MISSING killed pair(s) submitted: OK"

# ---- 5. the same config locally, compared
t_local=$(date +%s.%N)
python -m eval "${CONFIG[@]}" jobs=1 "reference.cache=$T/refs_local" "out_dir=$T/local" > "$T/local.log" 2>&1 \
  || { say "the local run failed"; exit 1; }
t_local=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_local")
python - "$T/local" "$ARR" "$REPO" <<'EOF'
import importlib.util
import sys
from pathlib import Path
import pandas as pd
a_dir, b_dir, repo = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
spec = importlib.util.spec_from_file_location("table_change", repo / "benchmarks" / "table_change.py")
tc = importlib.util.module_from_spec(spec)
spec.loader.exec_module(tc)
for name in ("cases.csv", "table.csv"):
    a, b = pd.read_csv(a_dir / name), pd.read_csv(b_dir / name)
    if "case" not in a:  # table.csv: one row per method
        a, b = a.assign(case="all"), b.assign(case="all")
    extra = sorted(set(a.columns) ^ set(b.columns))
    assert set(extra) <= {"cores"}, f"{name}: columns on one side only: {extra}"
    cols = tc.compared_columns(a, b)
    changes, unpaired = tc.table_change(a, b)
    assert not unpaired, f"{name}: rows on one side only: {unpaired}"
    assert not changes, f"{name}: non-time columns differ: {changes}"
    print(f"slurm-table-ci: {name}: {len(a)} rows, {len(cols)} non-time columns equal (local vs array)")
EOF
say "local and array tables equal in every non-time column: OK"

# ---- 6. the array again, uninterrupted, for its time beside the local run's
t_clean=$(date +%s.%N)
python -m eval "${CONFIG[@]}" "${ARRAY[@]}" "reference.cache=$T/refs_clean" "out_dir=$T/clean" > "$T/clean.log" 2>&1 \
  || { say "the uninterrupted array run failed"; exit 1; }
t_clean=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_clean")
python -c "import pandas as pd,sys; d=pd.read_csv(sys.argv[1], keep_default_na=False); assert len(d)==6 and (d.error=='').all()" \
  "$T/clean/cases.csv" || { say "the uninterrupted array run has error rows"; exit 1; }
say "times (this machine, $(nproc) CPUs, one node; each run computes its references): local jobs=1 ${t_local}s;" \
    "array ${t_clean}s; array with the kill ${t_array}s, then its resume ${t_resume}s"
say "PASSED in $(( $(date +%s) - T0 ))s"
