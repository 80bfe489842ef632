"""What the browser report of a run folder (:mod:`eval.report`) may show and link.

- :func:`run_cases`: the cases of the run the folder holds now (a resumed run keeps an
  earlier run's files, whose cases may differ).
- :func:`not_current`: why a 3D view or case figure in the folder is not this run's
  (of another case, or not written by this run: ``report/outputs.json``,
  :func:`eval.present.meshview.read_outputs`), or None when it is.
- :func:`link_target`: a relative path inside the folder as an ``href`` / ``src``
  value, percent-encoded, or None when it may not be linked.
"""
from __future__ import annotations

from pathlib import Path, PurePosixPath
from urllib.parse import quote

from eval.run.names import safe_name
from eval.run.runinfo import read_runinfo

__all__ = ["link_target", "run_cases", "not_current"]


def link_target(base, rel) -> str | None:
    """``rel`` as the value of an ``href`` / ``src`` attribute of a page in folder
    ``base``: the relative path percent-encoded (``/`` kept), so no part of it reads as a
    scheme (``javascript:x`` -> ``javascript%3Ax``), a query or a fragment; None (no
    link) when ``rel`` is empty, absolute, has a ``..`` part, a backslash or a control
    character, or leads outside ``base`` (through a symbolic link too).

    >>> link_target(".", "javascript:alert(1)"), link_target(".", "../x"), link_target(".", "/etc")
    ('javascript%3Aalert%281%29', None, None)
    """
    text = str(rel)
    path = PurePosixPath(text)
    if (not text or path.is_absolute() or ".." in path.parts or "\\" in text
            or any(ord(ch) < 32 or ord(ch) == 127 for ch in text)):
        return None
    root = Path(base).resolve()
    try:
        (root / path).resolve().relative_to(root)
    except (ValueError, OSError, RuntimeError):
        return None
    return quote(text, safe="/")


def run_cases(run_dir, info: dict | None = None) -> list[str] | None:
    """The names of the cases of the run ``run_dir`` holds now, in order: the keys of
    ``seeds.cases`` of its ``run.json`` (``info``: that file's content, when already
    read), else the ``case`` column of ``cases.csv``; None when neither names them
    (another experiment, a folder without them)."""
    run_dir = Path(run_dir)
    if info is None:
        info = read_runinfo(run_dir)
    seeds = info.get("seeds") if isinstance(info, dict) else None
    cases = seeds.get("cases") if isinstance(seeds, dict) else None
    if isinstance(cases, dict):
        return [str(c) for c in cases]
    try:
        import pandas as pd
        df = pd.read_csv(run_dir / "cases.csv", usecols=["case"], dtype=str, keep_default_na=False)
    except (OSError, ValueError, KeyError):
        return None
    return list(dict.fromkeys(df["case"]))


def not_current(kind: str, name: str, rel: str, cases, recorded, *, stem: bool = False) -> str | None:
    """Why the ``kind`` (``3D view``, ``figure``) file ``rel`` of case ``name`` is not
    this run's, in words, or None when it is.

    cases : the run's case names (:func:`run_cases`; None: unknown, any case).
    recorded : case name -> relative path of the file of that kind the run wrote
        (``report/outputs.json``; None: not recorded, any file of a case of the run).
    stem : ``name`` is a file stem, compared with the cases' :func:`eval.run.names.safe_name`.
    """
    if cases is not None:
        known = {safe_name(c): c for c in cases} if stem else {c: c for c in cases}
        if name not in known:
            return f"{kind} {rel} left out: not of a case of this run"
        name = known[name]
    if recorded is not None and recorded.get(name) != rel:
        return f"{kind} {rel} of case {name} left out: not drawn by this run"
    return None
