"""What a FAUST run's ``dataset`` section departs from in the paper's protocol (appendix A),
registered with :func:`eval.run.runinfo.register_departures` for ``run.json``'s
``departures``: ``dataset.protocol`` (the paper: 6 landmarks for targets 1-3) and
``dataset.n_targets`` (the paper: 4 targets per subject). Floor 2 of eval/ (eval/datasets/,
tests/test_layering.py); the registry finds this module on its own."""
from __future__ import annotations

from eval.run.runinfo import register_departures

__all__ = ["faust_departures"]


def faust_departures(section) -> list[str]:
    """The departures FAUST's section ``section`` (plain values) selects, as
    :func:`eval.run.runinfo.departures` writes them; empty at the paper's values.

    >>> faust_departures({"protocol": "paper", "n_targets": 3})
    ['dataset.n_targets=3 (paper: 4): targets per subject (appendix A)']
    """
    out = []
    if section.get("protocol", "paper") != "paper":
        out.append(f"dataset.protocol={section['protocol']} (paper: paper): every pose with all 11 landmarks, "
                   "not 6 for targets 1-3 (appendix A)")
    if section.get("n_targets", 4) != 4:
        out.append(f"dataset.n_targets={section['n_targets']} (paper: 4): targets per subject (appendix A)")
    return out


register_departures("faust", faust_departures)
