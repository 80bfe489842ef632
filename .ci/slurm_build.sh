#!/usr/bin/env bash
# CI: a DeFAUST build's subjects as one SLURM job array (python -m defaust ... cluster=slurm),
# for real, on a one-node cluster started here.
#
#   .ci/slurm_build.sh      (called by .ci/run)
#
# 1-2. starts a one-node SLURM in a temporary folder (.ci/slurm_cluster.sh: installs
#    slurm-wlm and munge with apt-get when absent, or skips this check, exit 0);
# 3. builds 3 synthetic subjects (preset=ci) through the array, one task per subject, and
#    kills task 2's Python process (kill -9) while it builds: the command must exit 2
#    naming the subject, with a partial manifest holding the other two;
# 4. runs the same command again: exactly one task (the killed subject) is submitted and
#    the build completes;
# 5. builds the same locally (workers=1) and checks that the two manifests are byte for
#    byte equal (every file's sha256) and that the array build verifies.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
REPO=$(pwd)
T0=$(date +%s)
say() { echo "slurm-build-ci [$(( $(date +%s) - T0 ))s]: $*"; }

CHECK="the SLURM build check"
LOGS=()
# shellcheck source=.ci/slurm_cluster.sh
source .ci/slurm_cluster.sh
LOGS=("$T/array.log" "$T/resume.log" "$T/local.log")

export PYTHONPATH="$REPO${PYTHONPATH:+:$PYTHONPATH}"
OUT="$T/build"
CONFIG=(source=synthetic preset=ci n_subjects=3 progress=false)
ARRAY=(cluster=slurm cluster.partition=debug cluster.cpus_per_task=1 cluster.mem_gb=1 cluster.timeout_min=20
       cluster.poll_s=1)

# ---- 3. the array, with task 2 killed while it builds
say "array: python -m defaust ${CONFIG[*]} ${ARRAY[*]} out=$OUT"
t_array=$(date +%s.%N)
python -m defaust "${CONFIG[@]}" "${ARRAY[@]}" "out=$OUT" > "$T/array.log" 2>&1 &
RUN=$!
KILLED=$(array_task_when "${OUT}_slurm" 1 "$RUN" true)   # task 2, once it runs
[ -n "$KILLED" ] || { say "task 2 never started"; exit 1; }
sleep 1   # inside its subject's work
kill -9 "$KILLED"
say "task 2 (python pid $KILLED) killed with kill -9"
rc=0
wait "$RUN" || rc=$?
t_array=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_array")
grep -E "submitted|array task|not built" "$T/array.log" || true
[ "$rc" -eq 2 ] || { say "the array command exited with $rc, expected 2 (a subject not built)"; exit 1; }
grep -q "1 subject(s) not built: subject 1: array task" "$T/array.log" \
  || { say "the command did not name subject 1 as not built"; exit 1; }
python - "$OUT" <<'PY'
import json, sys
m = json.load(open(f"{sys.argv[1]}/manifest.json"))
assert m["complete"] is False, "the manifest does not say partial"
assert sorted(v["subject"] for v in m["subjects"].values()) == [0, 2], m["subjects"].keys()
print("slurm-build-ci: partial manifest with subjects 0 and 2")
PY
say "array with a killed task: exit 2, subject 1 missing, manifest partial: OK"

# ---- 4. the same command again
t_resume=$(date +%s.%N)
python -m defaust "${CONFIG[@]}" "${ARRAY[@]}" "out=$OUT" > "$T/resume.log" 2>&1 \
  || { say "the resumed build failed"; exit 1; }
t_resume=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_resume")
grep -E "submitted|done:" "$T/resume.log" || true
grep -q "submitted 1 array task(s)" "$T/resume.log" && grep -q "done: 5 item(s) built, 10 skipped" "$T/resume.log" \
  || { say "the resume did not build exactly subject 1"; exit 1; }
say "resume: one task, subject 1's 5 items built, 10 kept: OK"

# ---- 5. the same build locally, compared byte for byte
t_local=$(date +%s.%N)
python -m defaust "${CONFIG[@]}" workers=1 "out=$T/local" > "$T/local.log" 2>&1 || { say "the local build failed"; exit 1; }
t_local=$(python -c "import sys,time; print(round(time.time() - float(sys.argv[1]), 1))" "$t_local")
cmp "$OUT/manifest.json" "$T/local/manifest.json" || { say "the array's manifest differs from the local one"; exit 1; }
python -m defaust verify "$OUT" || { say "the array build does not verify"; exit 1; }
say "array and local builds: manifests byte-identical (every checksum): OK"
say "times: local ${t_local}s, array with a killed task ${t_array}s, its resume ${t_resume}s"
say "OK"
