"""The evaluator's per-(case, method) result store: a run that stops (crash, ``kill -9``,
Ctrl-C, time limit) loses at most the pair it was computing (issue 21).

Layout, under the run's ``out_dir`` (:mod:`eval.outdir`)::

    runs/<case>/<method>.json      one finished (case, method) run (written atomically)
    runs/<case>/<method>.npy       its deformed vertices (n, 3) float64, with store.meshes=true

``<case>`` and ``<method>`` are the names with every character outside
``[A-Za-z0-9._+-]`` replaced by ``_`` (:func:`safe_name`). A record (JSON object) holds

- ``version`` (:data:`STORE_VERSION`), ``case``, ``method`` (the real names);
- ``key``: SHA-256 (hex) of ``key_fields``, which are what determines the result: the
  method's resolved definition (``_target_`` and parameters, :func:`eval.methods.method_spec`;
  a plug-in's mapping), the case's identity (dataset name, root, seed, case name and
  seed, hashes of the vertex/face arrays and of the handles and targets: :func:`case_identity`),
  the guard options and the reference options of the row (:func:`pair_key`);
- ``row``: the row of ``cases.csv`` (JSON: NaN/inf as null);
- ``info``: the method's own ``info`` (its stopping record: iterations, converged,
  protocol, per-sampling details ...), made JSON-safe (arrays as lists, other objects
  by their text);
- ``mesh``: the file name of the deformed vertices, or null;
- ``written_utc``.

Semantics: :meth:`ResultStore.load` returns a stored record only when its ``key`` equals
the pair's key now (a changed parameter, dataset or handle set makes the earlier record
stale: the pair is recomputed and its record replaced). The store never removes a record
it did not replace, except :meth:`ResultStore.clear` (a run without ``resume`` starts
from an empty store). Records are written with :func:`sshade.mesh.io.atomic_write`
(temporary file + rename): a killed run leaves whole records only.
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import re
from pathlib import Path

import numpy as np

from sshade.mesh.io import atomic_write

__all__ = ["STORE_VERSION", "STORE_DIR", "ResultStore", "safe_name", "case_identity", "pair_key", "json_safe"]

log = logging.getLogger("eval")

STORE_VERSION = 1  #: bumped when the record layout changes (an older record is then stale)
STORE_DIR = "runs"  #: the store's folder inside out_dir


def safe_name(name) -> str:
    """A file name for a case or method name: characters outside ``[A-Za-z0-9._+-]``
    become ``_``; a leading dot too (never a hidden file), at most 120 characters.

    >>> safe_name("SShaDe+refine"), safe_name("a/b c"), safe_name(".x")
    ('SShaDe+refine', 'a_b_c', '_x')
    """
    s = re.sub(r"[^A-Za-z0-9._+-]", "_", str(name))[:120]
    return "_" + s[1:] if s.startswith(".") else (s or "_")


def json_safe(v, depth: int = 0):
    """``v`` as plain JSON data: numpy scalars/arrays as Python numbers/lists, NaN and
    inf as None, mapping keys as text, anything else by its text (at most 500
    characters); nesting deeper than 8 levels becomes its text.

    >>> json_safe({"a": np.float64("nan"), 1: np.arange(2), "b": (True, 2.5)})
    {'a': None, '1': [0, 1], 'b': [True, 2.5]}
    """
    if isinstance(v, np.generic):
        v = v.item()
    if v is None or isinstance(v, (bool, int, str)):
        return v
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if depth > 8:
        return str(v)[:500]
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, dict):
        return {str(k): json_safe(x, depth + 1) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x, depth + 1) for x in v]
    return str(v)[:500]


def _digest(a) -> str:
    a = np.ascontiguousarray(np.asarray(a))
    return hashlib.sha256(f"{a.dtype.str}{a.shape}".encode() + a.tobytes()).hexdigest()[:16]


def case_identity(case, *, dataset: str, root, seed) -> dict:
    """What identifies a case: ``dataset`` (name), ``root`` (its folder, as text),
    ``seed`` (the dataset's seed), the case's ``name`` and ``seed``, and short SHA-256
    digests of its vertices ``V`` (n, 3), faces ``F`` (m, 3), ``handles`` (h,),
    ``targets`` (h, 3) (so a changed handle set is another case) and ground truth
    ``V_gt`` (n, 3) when it has one."""
    gt = getattr(case, "V_gt", None)
    return {"V_gt": None if gt is None else _digest(gt), "dataset": str(dataset), "root": str(root),
            "dataset_seed": json_safe(seed), "case": str(case.name),
            "case_seed": json_safe(getattr(case, "seed", None)), "V": _digest(case.V), "F": _digest(case.F),
            "handles": _digest(case.handles), "targets": _digest(case.targets)}


def pair_key(method_spec: dict, case_id: dict, extra: dict | None = None) -> tuple[str, dict]:
    """``(key, fields)``: the SHA-256 (hex) of the canonical JSON of ``fields`` =
    ``{"method": method_spec, "case": case_id, "extra": extra}`` (``extra``: the other
    options that change the row, e.g. the guard and reference settings)."""
    fields = {"version": STORE_VERSION, "method": json_safe(method_spec), "case": json_safe(case_id),
              "extra": json_safe(extra or {})}
    text = json.dumps(fields, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest(), fields


class ResultStore:
    """The store of one output folder (module docstring).

    Parameters
    ----------
    out_dir : the run's claimed output folder; the store is ``out_dir/runs``.
    meshes : bool, also store each successful run's deformed vertices (``.npy``).
    """

    def __init__(self, out_dir, *, meshes: bool = False):
        self.root = Path(out_dir) / STORE_DIR
        self.meshes = bool(meshes)

    def path(self, case: str, method: str) -> Path:
        """``runs/<case>/<method>.json`` (names through :func:`safe_name`)."""
        return self.root / safe_name(case) / f"{safe_name(method)}.json"

    def load(self, case: str, method: str, key: str) -> dict | None:
        """The stored record of (``case``, ``method``) when its key is ``key`` and it names
        that pair, else None (absent, unreadable, another version or a stale key)."""
        try:
            rec = json.loads(self.path(case, method).read_text())
        except (OSError, ValueError):
            return None
        ok = (isinstance(rec, dict) and rec.get("version") == STORE_VERSION and rec.get("key") == key
              and rec.get("case") == str(case) and rec.get("method") == str(method)
              and isinstance(rec.get("row"), dict))
        return rec if ok else None

    def load_mesh(self, rec: dict) -> np.ndarray | None:
        """The deformed vertices (n, 3) a record names, or None (not stored, unreadable)."""
        name = rec.get("mesh")
        if not name:
            return None
        try:
            return np.load(self.path(rec["case"], rec["method"]).with_name(str(name)), allow_pickle=False)
        except (OSError, ValueError):
            return None

    def save(self, case: str, method: str, key: str, fields: dict, row: dict, info=None, U=None) -> Path:
        """Store one finished run atomically (the mesh first, then the record naming it);
        returns the record's path. OSError propagates (the caller decides)."""
        p = self.path(case, method)
        p.parent.mkdir(parents=True, exist_ok=True)
        mesh = None
        if self.meshes and U is not None:
            mesh = p.with_suffix(".npy").name
            with atomic_write(p.with_suffix(".npy"), "wb") as fh:
                np.save(fh, np.asarray(U, dtype=np.float64), allow_pickle=False)
        rec = {"version": STORE_VERSION, "case": str(case), "method": str(method), "key": key, "key_fields": fields,
               "row": json_safe(row), "info": json_safe(info or {}), "mesh": mesh,
               "written_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        with atomic_write(p, "w") as fh:
            fh.write(json.dumps(rec, indent=1) + "\n")
        return p

    def clear(self) -> int:
        """Remove every record of the store and the meshes they name, then the folders
        left empty (a run that does not resume starts from nothing); files that are no
        records are kept. Returns the number of records removed."""
        n = 0
        if not self.root.is_dir() or self.root.is_symlink():
            return 0
        for p in sorted(self.root.glob("*/*.json")):
            try:
                rec = json.loads(p.read_text())
            except (OSError, ValueError):
                continue
            if not isinstance(rec, dict) or "version" not in rec or "key" not in rec:
                continue
            if rec.get("mesh"):
                p.with_name(safe_name(rec["mesh"])).unlink(missing_ok=True)
            p.unlink()
            n += 1
        for d in sorted(self.root.iterdir()):
            if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
                d.rmdir()
        if not any(self.root.iterdir()):
            self.root.rmdir()
        return n
