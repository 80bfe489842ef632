"""The plan's calibration to the machine (eval/run/machine_speed.py): the probe, the factor
it gives or the environment fixes, and the plan's times scaled by it."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from eval.run import machine_speed as ms
from eval.run.plan import make_plan, reference_s, render_plan
from eval.run.progress import CostModel, default_cost_model
from sshade.errors import SShaDeError


@pytest.fixture
def no_env(monkeypatch):
    monkeypatch.delenv(ms.SPEED_ENV, raising=False)
    ms._READINGS.clear()
    ms._ERRORS.clear()
    yield
    ms._READINGS.clear()
    ms._ERRORS.clear()


def test_probe_times_each_kind_asked_in_spawned_copies_and_refuses_bad_arguments():
    got = ms.probe_seconds(("runs",), repeats=1, copies=1)
    assert list(got) == ["runs"] and got["runs"] > 0
    for bad in (0, -1, 1.5, True, "3"):
        with pytest.raises(SShaDeError, match="repeats"):
            ms.probe_seconds(repeats=bad)
        with pytest.raises(SShaDeError, match="copies"):
            ms.probe_seconds(copies=bad)
    for kinds in ((), ("nope",), ("runs", "walk")):
        with pytest.raises(SShaDeError, match="kinds"):
            ms.probe_seconds(kinds)


def _fake_probe(calls, times=2.0, sleep=0.0):
    import time

    def probe(kinds):
        calls.append(tuple(kinds))
        time.sleep(sleep)  # a second thread asks meanwhile
        return {k: times * ms.PROBE_REFERENCE_S[k] for k in kinds}
    return probe


def test_probe_factor_is_its_seconds_over_the_reference_and_is_run_once_per_process(no_env, monkeypatch):
    import threading
    calls = []
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe(calls, sleep=0.2))
    got = []
    threads = [threading.Thread(target=lambda: got.append(ms.machine_speed())) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    a, b = got
    assert a == b == ms.machine_speed() and calls == [("runs",)]
    assert a["factor"] == a["build_factor"] == 2.0 and a["source"] == "probe" and not a["clipped"]
    assert a["probe_s"] == {"runs": pytest.approx(2.0 * ms.PROBE_REFERENCE_S["runs"])} and a["readings"] == {"runs": 1}


def test_the_build_is_probed_once_when_asked_and_has_its_own_factor(no_env, monkeypatch):
    calls = []
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe(calls))
    assert ms.machine_speed()["build_factor"] == 2.0 and calls == [("runs",)]
    ms._READINGS["runs"] = [3.0 * ms.PROBE_REFERENCE_S["runs"]]
    s = ms.machine_speed(build=True)
    assert calls == [("runs",), ("build",)] and (s["factor"], s["build_factor"]) == (3.0, 2.0)
    assert ms.machine_speed() == s and len(calls) == 2  # a later call without build keeps its factor
    assert "the runs x3 the priors, the build x2" in ms.speed_words(s)


@pytest.mark.parametrize("times, factor", [(1e-9, ms.SPEED_RANGE[0]), (1e9, ms.SPEED_RANGE[1])])
def test_a_probe_outside_the_range_is_clipped_and_says_so(no_env, monkeypatch, times, factor):
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe([], times=times))
    s = ms.machine_speed()
    assert s["factor"] == factor and s["clipped"]
    assert "clipped" in ms.speed_words(s)


def test_a_failed_probe_leaves_the_priors_as_they_are_and_says_why(no_env, monkeypatch):
    def broken(kinds):
        raise SShaDeError("a plan probe worker process died (SIGKILL)")
    monkeypatch.setattr(ms, "probe_seconds", broken)
    s = ms.machine_speed(build=True)
    assert (s["factor"], s["build_factor"], s["source"]) == (1.0, 1.0, "none")
    assert ms.speed_words(s).endswith("(the probe failed: a plan probe worker process died (SIGKILL))")


def test_the_environment_fixes_the_factor_without_a_probe(no_env, monkeypatch):
    monkeypatch.setattr(ms, "probe_seconds", lambda kinds: pytest.fail("the probe ran"))
    monkeypatch.setenv(ms.SPEED_ENV, "1.5")
    assert ms.machine_speed(build=True) == {"factor": 1.5, "build_factor": 1.5, "source": "env", "probe_s": None,
                                            "reference_s": ms.PROBE_REFERENCE_S, "clipped": False}


@pytest.mark.parametrize("raw", ["0", "-1", "nan", "inf", "fast"])
def test_a_bad_environment_value_is_refused_by_name(no_env, monkeypatch, raw):
    monkeypatch.setenv(ms.SPEED_ENV, raw)
    with pytest.raises(SShaDeError, match=ms.SPEED_ENV):
        ms.machine_speed()


def test_speed_scales_every_prior_and_guess_but_no_measured_cost():
    names = [SimpleNamespace(name=n) for n in ("ARAP", "SShaDe", "NoSuchPlugin")]
    one, two = default_cost_model(names), default_cost_model(names, speed=2.0)
    for n in ("ARAP", "SShaDe", "NoSuchPlugin"):
        for nv in (7_000, 170_000):
            assert two.estimate(n, nv) == pytest.approx(2.0 * one.estimate(n, nv))
    for m in (one, two):
        m.observe("ARAP", 100_000, 30.0)
    assert two.estimate("ARAP", 150_000) == one.estimate("ARAP", 150_000)


def test_the_plan_scales_its_references_with_the_cost_model_and_names_its_calibration():
    assert reference_s(50_000, speed=3.0) == pytest.approx(3.0 * reference_s(50_000))
    cases = [SimpleNamespace(n_vertices=50_000)]
    refs = [(50_000, "spokes", False)]
    p1 = make_plan(cases, ["ARAP"], [(0, 0)], CostModel({}, priors={"ARAP": 1e-4}), references=refs)
    p3 = make_plan(cases, ["ARAP"], [(0, 0)], CostModel({}, priors={"ARAP": 1e-4}, speed=3.0), references=refs)
    assert p3["total_s"] == pytest.approx(3.0 * p1["total_s"])
    p3["speed"] = {"factor": 3.0, "build_factor": 3.0, "source": "env", "probe_s": None, "reference_s": {},
                   "clipped": False}
    line = render_plan(p3)
    assert line.endswith(f"in all ({ms.speed_words(p3['speed'])}).")
    assert "x3" in line


def test_probe_copies_follow_the_cores_but_no_more_than_the_free_memory_holds(monkeypatch):
    monkeypatch.setattr(ms, "available_cores", lambda: 16)
    monkeypatch.setattr(ms, "_free_bytes", lambda: None)
    assert ms.probe_copies() == ms.MAX_PROBE_COPIES
    monkeypatch.setattr(ms, "_free_bytes", lambda: 3 * ms.PROBE_COPY_BYTES + 1)
    assert ms.probe_copies() == 3
    monkeypatch.setattr(ms, "_free_bytes", lambda: 0)
    assert ms.probe_copies() == 1
    monkeypatch.setattr(ms, "available_cores", lambda: 2)
    monkeypatch.setattr(ms, "_free_bytes", lambda: 64 * ms.PROBE_COPY_BYTES)
    assert ms.probe_copies() == 2


def test_probing_again_takes_the_mean_of_this_process_readings_of_the_runs(no_env, monkeypatch):
    calls = []
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe(calls))
    first = ms.machine_speed(build=True)
    assert first["factor"] == 2.0 and first["readings"] == {"runs": 1, "build": 1}
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe(calls, times=4.0))
    s = ms.machine_speed(again=True)
    assert calls == [("runs", "build"), ("runs",)]  # the build's reading is not taken again
    assert (s["factor"], s["build_factor"]) == (3.0, 2.0) and s["readings"] == {"runs": 2, "build": 1}
    assert ms.machine_speed() == s and len(calls) == 2
    monkeypatch.setattr(ms, "probe_seconds", lambda kinds: (_ for _ in ()).throw(SShaDeError("died")))
    assert ms.machine_speed(again=True)["factor"] == 3.0  # a failed probe again keeps the readings


def test_a_plan_under_the_floor_runs_no_probe_and_says_it_uses_the_priors(no_env, monkeypatch):
    calls = []
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe(calls))
    s = ms.machine_speed(build=True, again=True, probe=False)
    assert calls == [] and (s["factor"], s["build_factor"], s["source"]) == (1.0, 1.0, "short")
    assert f"not probed: the plan is under {ms.PROBE_MIN_PLAN_S:g} s" in ms.speed_words(s)
    ms.machine_speed()  # a later long plan probes; a short one then takes its reading, no build probed
    s = ms.machine_speed(build=True, again=True, probe=False)
    assert calls == [("runs",)] and s["source"] == "probe" and s["factor"] == 2.0 and "build" not in s["probe_s"]


def test_plan_speed_probes_a_long_plan_or_a_build_and_not_a_short_plan(no_env, monkeypatch):
    from eval.experiments.cases.case_plan import plan_speed
    calls = []
    monkeypatch.setattr(ms, "probe_seconds", _fake_probe(calls))
    methods = [SimpleNamespace(name="ARAP")]
    cost = default_cost_model(methods)
    short = [("ARAP", 6890)] * max(1, int(0.5 * ms.PROBE_MIN_PLAN_S / cost.estimate("ARAP", 6890)))
    assert sum(cost.estimate(n, v) for n, v in short) < ms.PROBE_MIN_PLAN_S
    assert plan_speed(methods, short)["source"] == "short" and calls == []
    assert plan_speed(methods, short * 3)["source"] == "probe" and calls == [("runs",)]
    ms._READINGS.clear()
    assert plan_speed(methods, short, build=True)["source"] == "probe" and calls[-1] == ("runs", "build")
