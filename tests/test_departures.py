"""run.json's `departures` (eval/run/runinfo.py): the switches at non-paper values."""
from __future__ import annotations

from pathlib import Path

from eval.datasets import datasets
from eval.run.runinfo import collect_runinfo, departures

datasets()  # every dataset module imported: FAUST registers its section's departures

PAPER = {"sshade": {"gradient": "raw", "warm_start": False}, "arap": {"protocol": "paper"},
         "dataset": {"name": "faust", "protocol": "paper", "n_targets": 4}}


def _keys(config):
    return [d.split("=")[0] for d in departures(config)]


def test_paper_config_has_no_departure():
    assert departures(PAPER) == []
    assert departures({}) == []


def test_defaults_list_each_switch():
    cfg = {"sshade": {"gradient": "normalized", "warm_start": True}, "arap": {"protocol": "converged"},
           "dataset": {"name": "faust", "protocol": "all_landmarks", "n_targets": 3}}
    assert _keys(cfg) == ["sshade.gradient", "sshade.warm_start", "arap.protocol", "dataset.protocol",
                          "dataset.n_targets"]
    assert "(paper: raw)" in departures(cfg)[0] and "(paper: false)" in departures(cfg)[1]
    # the defaust dataset has no protocol switch here
    assert _keys({"dataset": {"name": "defaust", "protocol": "x"}}) == []


def test_no_dataset_is_named_below_its_own_modules():
    """FAUST's rule lives in eval/datasets/ (registered), not in the ground floor's runinfo."""
    text = (Path(__file__).resolve().parents[1] / "eval" / "run" / "runinfo.py").read_text()
    assert '"faust"' not in text and "'faust'" not in text


def test_method_sections_win_over_the_shared_ones():
    cfg = {"methods": ["Elastic", "SShaDe"], "sshade": {"gradient": "raw"},
           "method": {"Elastic": {"protocol": "converged"},
                      "SShaDe": {"gradient": "normalized", "warm_start": False, "protocol": "paper"},
                      "ARAP": {"protocol": "converged"}}}  # not run: not listed
    assert _keys(cfg) == ["method.Elastic.protocol", "method.SShaDe.gradient"]


def test_recorded_in_runinfo():
    info = collect_runinfo({"arap": {"protocol": "converged"}})
    assert info["departures"] == departures({"arap": {"protocol": "converged"}})
    assert list(info).index("departures") == list(info).index("config") + 1


def test_plugin_methods_are_skipped():
    """A plug-in in ``methods`` is a mapping (no ``method.<name>`` section): no departure, no crash."""
    from eval.run.runinfo import departures
    cfg = {"methods": ["SShaDe", {"_target_": "x.Y", "name": "Mine"}],
           "method": {"SShaDe": {"gradient": "raw", "warm_start": False, "protocol": "paper"}}}
    assert departures(cfg) == []
