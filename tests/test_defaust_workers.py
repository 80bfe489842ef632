"""DeFAUST builder in worker processes (``workers=N``): the same files whatever the worker
count, resumable, one error for a failing job (synthetic source, ``preset=ci``, 2 subjects).

The manifest has no timing field (timings are only in the returned BuildReport), so
every file, ``manifest.json`` included, is compared byte for byte.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import time

import pytest

from defaust.build import build_defaust
from defaust.cli import compose_config, config_from_omegaconf
from defaust.config import BuildConfig
from defaust.store import sha256_file
from harness.jobs import THREAD_VARIABLES, JobOptions, run_jobs, send, thread_limit
from sshade.cores import pool_size
from sshade.errors import SShaDeError


def _build(out, workers, *extra):
    cfg = compose_config(["preset=ci", "source=synthetic", f"out={out}", "n_subjects=2", "progress=false",
                          f"workers={workers}", *extra])
    return build_defaust(config_from_omegaconf(cfg))


def _digests(out) -> dict:
    return {str(p.relative_to(out)): sha256_file(p) for p in sorted(out.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("defaust_w1")
    return out, _build(out, 1)


@pytest.mark.slow
def test_two_workers_build_the_same_files_as_one(serial, tmp_path):
    out1, rep1 = serial
    rep2 = _build(tmp_path, 2)
    d1, d2 = _digests(out1), _digests(tmp_path)
    assert len(d1) == 2 + 2 * (2 + 4 * 3)  # manifest, croissant + per subject 2 rest files + 4 poses x 3 files
    assert d2 == d1  # every file, manifest.json and croissant.json included
    assert rep2.built == rep1.built and rep2.skipped == [] and sorted(rep2.subject_seconds) == [0, 1]
    assert rep2.manifest == rep1.manifest


@pytest.mark.slow
def test_parallel_build_resumes_and_repairs(serial, tmp_path):
    out1, _ = serial
    _build(tmp_path, 2)
    (tmp_path / "subject_01" / "pose_03_high.ply").unlink()  # a lost file: only its item is rebuilt
    rep = _build(tmp_path, 2)
    assert rep.built == ["subject_01/pose_03"] and len(rep.skipped) == 9
    rep = _build(tmp_path, 2)  # complete: verified in this process, nothing built
    assert rep.built == [] and len(rep.skipped) == 10
    assert _digests(tmp_path) == _digests(out1)


def test_workers_is_checked_and_not_a_dataset_parameter(tmp_path):
    with pytest.raises(SShaDeError, match="workers"):
        config_from_omegaconf(compose_config(["preset=ci", f"out={tmp_path}", "workers=0"]))
    with pytest.raises(SShaDeError, match="workers"):
        BuildConfig(out=tmp_path, workers=1.5).validate()
    assert "workers" not in BuildConfig(out=tmp_path, source="synthetic", workers=3).parameters()


def test_pool_size_and_threads():
    assert pool_size(8, 3) == 3 and pool_size(1, 10) == 1 and pool_size(None, 0) == 1
    assert thread_limit(1) >= 1 and thread_limit(10_000) == 1


# module-level jobs: the spawned workers import them from this module

def _square(x):
    send(("seen", x))
    return x * x, {k: os.environ.get(k) for k in THREAD_VARIABLES}


def _fail_on_two(x):
    if x == 2:
        raise SShaDeError(f"job {x} failed")
    return x


def test_run_jobs_results_messages_and_thread_limit():
    results, messages = {}, []
    run_jobs(_square, [(1,), (2,), (3,)], workers=2, on_message=messages.append,
             on_result=lambda i, r: results.__setitem__(i, r))
    assert {i: r[0] for i, r in results.items()} == {0: 1, 1: 4, 2: 9}
    assert sorted(messages) == [("seen", 1), ("seen", 2), ("seen", 3)]
    want = str(thread_limit(2))
    assert all(env == {k: want for k in THREAD_VARIABLES} for _, env in results.values())
    results.clear()  # only the variables named are set; the others keep this process's values
    run_jobs(_square, [(1,), (2,)], workers=2, on_result=lambda i, r: results.__setitem__(i, r),
             options=JobOptions(thread_variables=("NUMBA_NUM_THREADS",)))
    here = os.environ.get("OPENBLAS_NUM_THREADS")
    assert all(env["NUMBA_NUM_THREADS"] == want and env["OPENBLAS_NUM_THREADS"] == here for _, env in results.values())


def _sleep(x):
    send(("started", x))
    time.sleep(120)


def test_a_failing_job_raises_its_error_once_and_stops_the_rest():
    with pytest.raises(SShaDeError, match="^job 2 failed$"):
        run_jobs(_fail_on_two, [(2,), (1,)], workers=2)
    got = []
    with pytest.raises(SShaDeError, match="^job 2 failed$"):  # one worker: jobs in order
        run_jobs(_fail_on_two, [(1,), (2,), (3,), (4,)], workers=1, on_result=lambda i, r: got.append(r))
    assert got == [1]  # jobs 3 and 4 were never started


def test_ctrl_c_terminates_the_workers_at_once():
    def interrupt(msg):
        raise KeyboardInterrupt

    before = set(mp.active_children())
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        run_jobs(_sleep, [(1,), (2,)], workers=2, on_message=interrupt)
    assert time.perf_counter() - t0 < 60  # not the jobs' 120 s
    assert set(mp.active_children()) <= before
