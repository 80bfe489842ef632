"""The exchange layout: every case of a dataset in files any language reads, and the
names a folder of results computed elsewhere follows.
Floor 2 of eval/ (eval/exchange/, tests/test_layering.py); notes: docs/implementation.md.

An export folder (:func:`write_export`) holds ``cases.json`` (:data:`INDEX`) and one folder
per case (``<case>/rest.obj``, ``rest.ply``, ``handles.json``, ``handles.csv``, ``handles.dmat``,
``targets.dmat``, ``static.dmat``), named exactly as the evaluator names the case. A results
folder holds one deformed mesh per case, ``<case>.obj`` (or ``.ply``, ``.off``;
:func:`result_path`), and optionally a times file (:func:`read_times`)."""
from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import stat
from pathlib import Path
from typing import NamedTuple

import numpy as np

from defaust.store import sha256_file
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.json_file import read_bounded
from sshade.mesh.io import write_mesh

__all__ = ["FORMAT", "INDEX", "CASE_FILES", "RESULT_EXTS", "TIMES_COLUMNS", "MAX_TIMES_BYTES", "MAX_TIME_S",
           "ReportedRun", "machine_text", "write_case",
           "write_export", "result_path", "read_times"]

FORMAT = "sshade-exchange/1"   #: ``format`` of :data:`INDEX`
INDEX = "cases.json"           #: the export's index of cases
#: Files of one case folder, key -> file name (the keys of ``files`` in :data:`INDEX`).
CASE_FILES = {"rest_obj": "rest.obj", "rest_ply": "rest.ply", "handles_json": "handles.json",
              "handles_csv": "handles.csv", "handles_dmat": "handles.dmat", "targets_dmat": "targets.dmat",
              "static_dmat": "static.dmat"}
#: Extensions of a result mesh, in the order they are looked for (exactly one per case).
RESULT_EXTS = (".obj", ".ply", ".off")  #: STL is refused: it keeps no shared vertices, so no vertex order
#: Columns of a times file: the case, the method's own seconds for it, the machine.
TIMES_COLUMNS = ("case", "time_s", "machine", "iterations", "converged")
MAX_TIMES_BYTES = 16 << 20     #: a times file larger than this is refused (counted as read)
MAX_TIME_S = 1e7               #: a reported time above this (115 days) is refused: their mean would overflow


def _write_dmat(path: Path, A: np.ndarray) -> None:
    """``A`` (r, c) as libigl's ASCII DMAT (``igl.writeDMAT``), written atomically."""
    import igl
    tmp = path.with_name(f".{path.name}.tmp")
    if not igl.writeDMAT(str(tmp), np.ascontiguousarray(A, np.float64), True):
        raise OSError(f"{tmp}: igl.writeDMAT failed")
    os.replace(tmp, path)


def write_case(folder, case) -> dict:
    """Write one case (:class:`eval.datasets.deformation_case.DeformationCase`) into ``folder`` (created).

    Parameters
    ----------
    folder : str or Path, the case's folder (its files: :data:`CASE_FILES`).
    case : the case: ``name``, ``subject``, ``pose``, ``V`` (n, 3) float64, ``F`` (m, 3)
        int64, ``handles`` (h,) int64, ``targets`` (h, 3) float64, ``static`` (h,) bool,
        ``group`` (h,) int64 or None. Its ``V_gt`` is not written.

    Returns
    -------
    dict: the case's entry of :data:`INDEX` (name, subject, pose, sizes, ``files`` key ->
    path relative to the export folder, ``sha256`` key -> digest).

    Raises
    ------
    OSError when a file cannot be written; SShaDeError on arrays of the wrong shape.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    h = np.asarray(case.handles, np.int64).reshape(-1)
    T = np.asarray(case.targets, np.float64).reshape(-1, 3)
    static = np.asarray(case.static, bool).reshape(-1)
    group = None if getattr(case, "group", None) is None else np.asarray(case.group, np.int64).reshape(-1)
    write_mesh(folder / CASE_FILES["rest_obj"], case.V, case.F)
    write_mesh(folder / CASE_FILES["rest_ply"], case.V, case.F)
    doc = {"case": case.name, "n_vertices": len(case.V), "n_faces": len(case.F), "index_base": 0,
           "handles": h.tolist(), "targets": T.tolist(), "static": static.tolist(),
           "group": None if group is None else group.tolist()}
    with atomic_write(folder / CASE_FILES["handles_json"]) as f:
        json.dump(doc, f)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["handle", "x", "y", "z", "static", "group"])
    for i in range(len(h)):
        w.writerow([int(h[i]), *(repr(float(x)) for x in T[i]), int(static[i]),
                    "" if group is None else int(group[i])])
    with atomic_write(folder / CASE_FILES["handles_csv"]) as f:
        f.write(buf.getvalue())
    _write_dmat(folder / CASE_FILES["handles_dmat"], h.reshape(-1, 1))
    _write_dmat(folder / CASE_FILES["targets_dmat"], T)
    _write_dmat(folder / CASE_FILES["static_dmat"], static.astype(np.float64).reshape(-1, 1))
    subject = case.subject if isinstance(case.subject, str) else int(case.subject)
    pose = case.pose if isinstance(case.pose, str) else int(case.pose)
    files = {k: f"{folder.name}/{v}" for k, v in CASE_FILES.items()}
    return {"name": case.name, "subject": subject, "pose": pose, "n_vertices": len(case.V), "n_faces": len(case.F),
            "n_handles": len(h), "n_static": int(static.sum()), "has_ground_truth": case.V_gt is not None,
            "files": files, "sha256": {k: sha256_file(folder / v) for k, v in CASE_FILES.items()}}


def write_export(out_dir, cases, *, dataset: dict) -> Path:
    """Write every case of ``cases`` into ``out_dir/<case.name>/`` and the index
    :data:`INDEX`; returns the index's path.

    Parameters
    ----------
    out_dir : str or Path, a folder already claimed for this output (it exists).
    cases : list of cases (:func:`write_case`), names unique as the evaluator makes them.
    dataset : what the index says of the data: name, root, options, manifest sha256.

    Raises
    ------
    OSError when a file cannot be written.
    """
    out = Path(out_dir)
    entries = [write_case(out / c.name, c) for c in cases]
    index = {"format": FORMAT, "dataset": dataset, "cases": entries,
             "results": {"file": "<results>/<name>.obj (or .ply, .off; not .stl, which keeps no vertex order): the "
                                 "deformed rest mesh, its vertices in the rest mesh's order and its faces those of "
                                 "the rest mesh (a file of vertices only is refused)",
                         "times": "optional CSV with columns case,time_s[,machine,iterations,converged]: the "
                                  "method's own seconds per case, and how it stopped"}}
    with atomic_write(out / INDEX) as f:
        json.dump(index, f, indent=1)
    return out / INDEX


def result_path(results, name: str) -> Path:
    """The result mesh of case ``name`` in folder ``results``: the one file
    ``<name>.<ext>`` with ``ext`` in :data:`RESULT_EXTS` (any case of the extension).

    Raises
    ------
    SShaDeError when there is none (naming the names looked for), more than one, or it is
    a link (never followed), a folder, a FIFO or a device.
    """
    results = Path(results)
    want = {f"{name}{e}".lower() for e in RESULT_EXTS}
    try:
        found = sorted(p for p in os.listdir(results) if p.lower() in want)
    except OSError as e:
        raise SShaDeError(f"{results}: cannot list the results folder ({e.strerror or type(e).__name__})") from None
    if not found:
        stl = [p for p in os.listdir(results) if p.lower() == f"{name}.stl".lower()]
        if stl:
            raise SShaDeError(f"{results / stl[0]}: an STL result cannot be scored (it stores each triangle's corners "
                              "apart, in float32: the rest mesh's vertex order is lost); write OBJ, PLY or OFF")
        raise SShaDeError(f"no result for case {name}: {results} has no {name}.obj (nor .ply, .off)")
    if len(found) > 1:
        raise SShaDeError(f"two results for case {name} in {results}: {', '.join(found)}; keep one")
    p = results / found[0]
    try:
        st = os.lstat(p)
    except OSError as e:
        raise SShaDeError(f"{p}: cannot read it ({e.strerror or type(e).__name__})") from None
    if stat.S_ISLNK(st.st_mode):  # never followed: a link to /etc/passwd would land in the tables
        raise SShaDeError(f"{p} is a link (to {os.readlink(p)}); a result must be a regular file in {results}: "
                          "copy it there")
    if not stat.S_ISREG(st.st_mode):
        raise SShaDeError(f"{p} is not a regular file (a folder, a FIFO or a device); a result must be a mesh file")
    return p


def _time(v: str, where: str) -> float:
    try:
        t = float(v)
    except ValueError:
        raise SShaDeError(f"{where}: time_s {v!r} is not a number") from None
    if not (math.isfinite(t) and 0 <= t <= MAX_TIME_S):
        raise SShaDeError(f"{where}: time_s {v!r} must be a number of seconds in [0, {MAX_TIME_S:g}]")
    return t


def machine_text(v: str) -> str:
    """A reported machine name as plain text for CSV, Markdown and HTML: spaces collapsed,
    characters outside letters, digits and ``space . _ , : ( ) / # + -`` replaced by ``_``,
    no leading ``+`` or ``-`` (a spreadsheet formula), at most 200 characters.

    >>> machine_text("=cmd|' /C calc'!A0"), machine_text("<script>x</script>")
    ('_cmd__ /C calc__A0', '_script_x_/script_')
    """
    s = re.sub(r"[^A-Za-z0-9 ._,:()/#+-]", "_", " ".join(str(v).split()))[:200]
    return s.lstrip("+-")


class ReportedRun(NamedTuple):
    """What a method reported of one case's run (a line of its times file): ``time_s``
    (seconds), ``machine`` (:func:`machine_text`, ``""`` when not given), how it stopped:
    ``iterations`` (int >= 0) and ``converged`` (bool: its stopping criterion met, False:
    a cap or a budget stopped it), None where not given."""
    time_s: float
    machine: str
    iterations: int | None = None
    converged: bool | None = None


def read_times(path) -> dict[str, ReportedRun]:
    """The times a method reported for its cases: a CSV with a header line naming the
    columns ``case`` and ``time_s`` (seconds, >= 0) and optionally ``machine`` (text),
    ``iterations`` (an integer >= 0) and ``converged`` (true/false, 1/0, yes/no), these
    two cells may be empty.

    Returns
    -------
    dict: case name -> :class:`ReportedRun`.

    Raises
    ------
    SShaDeError naming the file and line: unreadable, not a regular file, larger than
    :data:`MAX_TIMES_BYTES` (counted as read), no ``case``/``time_s`` column, a time that
    is not a number of seconds in [0, :data:`MAX_TIME_S`], an iteration count or a
    converged flag that is not one, a case listed twice.
    """
    p = Path(path)
    try:
        text = read_bounded(p, MAX_TIMES_BYTES).decode("utf-8-sig")  # a FIFO or a device refused, not read
    except OSError as e:
        raise SShaDeError(f"{p}: unreadable times file ({e.strerror or type(e).__name__})") from None
    except UnicodeDecodeError as e:
        raise SShaDeError(f"{p}: not a UTF-8 text file (byte {e.start})") from None
    rows = list(csv.reader(io.StringIO(text)))
    head = [c.strip().lower() for c in rows[0]] if rows else []
    if "case" not in head or "time_s" not in head:
        raise SShaDeError(f"{p}, line 1: the header must name the columns case,time_s[,machine], got {head}")
    ic, it = head.index("case"), head.index("time_s")
    col = {c: head.index(c) if c in head else None for c in ("machine", "iterations", "converged")}
    out: dict = {}
    for i, r in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in r):
            continue
        if len(r) != len(head):
            raise SShaDeError(f"{p}, line {i}: {len(r)} cells, the header has {len(head)}")
        name = r[ic].strip()
        if name in out:
            raise SShaDeError(f"{p}, line {i}: case {name!r} listed twice")
        cell = {c: (r[j].strip() if j is not None else "") for c, j in col.items()}
        where = f"{p}, line {i}"
        out[name] = ReportedRun(_time(r[it].strip(), where), machine_text(cell["machine"]),
                                _count(cell["iterations"], where), _flag(cell["converged"], where))
    return out


def _count(v: str, where: str) -> int | None:
    if not v:
        return None
    if not v.isdigit() or len(v) > 12:
        raise SShaDeError(f"{where}: iterations {v!r} is not an integer >= 0")
    return int(v)


def _flag(v: str, where: str) -> bool | None:
    if not v:
        return None
    f = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}.get(v.lower())
    if f is None:
        raise SShaDeError(f"{where}: converged {v!r} is not true or false")
    return f
