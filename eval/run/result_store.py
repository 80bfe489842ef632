"""The evaluator's per-(case, method) result store: a run that stops (crash, ``kill -9``,
Ctrl-C, time limit) loses at most the pair it was computing.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

Layout, under the run's ``out_dir`` (:mod:`eval.run.outdir`)::

    runs/<case>/<method>.json      one finished (case, method) run (written atomically)
    runs/<case>/<method>.npy       its deformed vertices (n, 3) float64, with store.meshes=true

``<case>`` and ``<method>`` are the names with every character outside
``[A-Za-z0-9._+-]`` replaced by ``_`` (:func:`eval.run.names.safe_name`). A record (JSON object) holds"""
from __future__ import annotations

import datetime as _dt
import hashlib
import json
import logging
import math
import os
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from eval.run.jsonsafe import json_safe
from eval.run.names import safe_name
from eval.run.outdir import alive
from eval.run.runinfo import git_info, machine_info
from sshade.errors import SShaDeError
from sshade.files import atomic_write, inside_folder
from sshade.json_file import open_regular, read_json

__all__ = ["STORE_VERSION", "STORE_DIR", "RECORD_EXTRAS", "LATER_CASE_FIELDS", "OTHER_SETTINGS", "ResultStore",
           "Lookup",
           "case_identity", "pair_key",
           "check_row", "cell_problem", "record_digest", "output_digest", "fields_digest", "numeric_column",
           "describe_change", "other_case_data"]

log = logging.getLogger("eval")

#: The record format's version, bumped when what the modules that only store, run or present
#: records (:data:`eval.run.code_identity.RECORD_ONLY`) write or key changes: their source is
#: not part of a row's code identity, this number is (an older record is then stale, or re-keyed
#: by ``python -m eval.reproduce --rekey`` where git still has the code that made it)
STORE_VERSION = 6
STORE_DIR = "runs"  #: the store's folder inside out_dir

#: The fields a record may hold besides its row, covered by its digest where present:
#: ``output`` (:func:`output_digest` of the deformed vertices), ``reference`` (the
#: reference the row was scored against: energy, cache key, content digest) and
#: ``reproduced`` (the row kept by a later commit whose reference came out bit for bit the
#: same: :mod:`eval.experiments.cases.reference_cutoff`) and ``same_output_as`` (the record
#: it replaced, of other code or settings, whose output had the very same bytes: its
#: ``commit`` and ``key``).
RECORD_EXTRAS = ("output", "reference", "reproduced", "same_output_as")


def _digest(a) -> str:
    a = np.ascontiguousarray(np.asarray(a))
    return hashlib.sha256(f"{a.dtype.str}{a.shape}".encode() + a.tobytes()).hexdigest()[:16]


#: The case fields a record's key holds since they were added (:func:`case_identity`); a
#: record stored before lacks them and is matched without them (:meth:`ResultStore.lookup`).
LATER_CASE_FIELDS = ("static", "group")


def case_identity(case, *, dataset: str, seed) -> dict:
    """What identifies a case: ``dataset`` (name), ``seed`` (the dataset's seed), the
    case's ``name``, ``seed``, ``subject``, ``pose`` and ``n_dropped`` (the row's columns
    taken from the case), and short SHA-256 digests of
    its vertices ``V`` (n, 3), faces ``F`` (m, 3), ``handles`` (h,), ``targets`` (h, 3)
    (so a changed handle set is another case), ground truth ``V_gt`` (n, 3) when it
    has one, and what a case-aware method is told besides (``static`` (h,) bool, ``group``
    (h,) int64 or None; :func:`eval.datasets.deformation_case.case_label`), so no loader
    need be part of a row's identity. Not the folder it was read from: the same data read
    from another folder (a clean checkout elsewhere, a build copied to another machine) is
    the same case."""
    gt, group, static = getattr(case, "V_gt", None), getattr(case, "group", None), getattr(case, "static", None)
    later = {"static": None if static is None else _digest(np.asarray(static, bool)),
             "group": None if group is None else _digest(np.asarray(group, np.int64))}
    return {"V_gt": None if gt is None else _digest(gt), "dataset": str(dataset),
            "dataset_seed": json_safe(seed), "case": str(case.name),
            "case_seed": json_safe(getattr(case, "seed", None)), "V": _digest(case.V), "F": _digest(case.F),
            "handles": _digest(case.handles), "targets": _digest(case.targets),
            "subject": json_safe(getattr(case, "subject", None)), "pose": json_safe(getattr(case, "pose", None)),
            "n_dropped": json_safe(getattr(case, "n_dropped", None)), **later}


#: The fields of a case's identity that are its data (:func:`case_identity`): a record whose
#: digests of these differ from a run's ran on other meshes, handles or targets.
CASE_DATA_FIELDS = ("V", "F", "handles", "targets", "V_gt", *LATER_CASE_FIELDS)


def other_case_data(rec, fields: dict | None) -> bool:
    """Whether stored record ``rec`` ran on other data than the case of ``fields`` (a
    pair's key fields now, :func:`pair_key`): any of :data:`CASE_DATA_FIELDS` its case
    identity holds differs (a field it lacks, stored before it was keyed, is not compared).
    A record without a case identity counts as other data."""
    old = (rec.get("key_fields") or {}).get("case") if isinstance(rec, dict) and isinstance(
        rec.get("key_fields"), dict) else None
    new = (fields or {}).get("case") if isinstance(fields, dict) else None
    if not isinstance(old, dict) or not isinstance(new, dict):
        return True
    return any(old[k] != new.get(k) for k in CASE_DATA_FIELDS if k in old)


def fields_digest(fields) -> str:
    """SHA-256 (hex) of the canonical JSON of a record's key fields: its ``key``
    (:func:`pair_key`)."""
    return hashlib.sha256(json.dumps(fields, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def pair_key(method_spec: dict, case_id: dict, extra: dict | None = None, code: dict | None = None
             ) -> tuple[str, dict]:
    """``(key, fields)``: the SHA-256 (hex) of the canonical JSON of ``fields`` =
    ``{"method": method_spec, "case": case_id, "extra": extra, "code": code}``
    (``extra``: the other options that change the row, e.g. the guard and reference
    settings; ``code``: :func:`eval.run.code_identity.code_identity` of the method)."""
    fields = {"version": STORE_VERSION, "method": json_safe(method_spec), "case": json_safe(case_id),
              "extra": json_safe(extra or {}), "code": json_safe(code)}
    return fields_digest(fields), fields


_NUMERIC = re.compile(r"^(n_\w+|\w+_(pct|s|deg|mb|err))$")
_NON_NEGATIVE = re.compile(r"^(n_\w+|time_s|compile_s|\w+_deg|\w+_mb)$")


def numeric_column(name: str) -> bool:
    """Whether a row column must hold a number (or be empty): counts ``n_*``, seconds
    ``*_s``, percentages ``*_pct``, angles ``*_deg``, megabytes ``*_mb``, errors ``*_err``;
    a method's own info columns renamed ``info_*`` are free.

    >>> numeric_column("volume_err_pct"), numeric_column("time_s"), numeric_column("info_time_s")
    (True, True, False)
    """
    return not name.startswith("info_") and bool(_NUMERIC.match(name))


def cell_problem(name: str, v) -> str:
    """``""`` when ``v`` may stand in column ``name`` of a stored row, else why not: a
    cell is None, a bool, a finite number or a text; a numeric column
    (:func:`numeric_column`) holds a number or nothing, non-negative for counts, times,
    angles and megabytes.

    >>> cell_problem("volume_err_pct", "abc"), cell_problem("n_handles", 3)
    ("volume_err_pct is not a number ('abc')", '')
    """
    if v is not None and not isinstance(v, (bool, int, float, str)):
        return f"{name} is not a table cell ({type(v).__name__})"
    if isinstance(v, float) and not math.isfinite(v):
        return f"{name} is not finite"
    if numeric_column(name) and v is not None:
        if isinstance(v, (bool, str)):
            return f"{name} is not a number ({v!r:.40})"
        if _NON_NEGATIVE.match(name) and v < 0:
            return f"{name} is negative ({v})"
    return ""


def check_row(row, case: str, method: str) -> str:
    """``""`` when ``row`` is a valid stored row of (``case``, ``method``), else what is
    wrong, in words: a mapping naming that case and method, with a text ``error``; every
    cell None, a bool, a finite number or a text; numeric columns (:func:`numeric_column`)
    numbers or empty, times, counts, angles and megabytes non-negative; a row without an
    error has its ``time_s`` (unless it was computed elsewhere, ``time_reported``, and its
    method reported no time).

    >>> check_row({"case": "c", "method": "A", "error": "", "time_s": -1.0}, "c", "A")
    'time_s is negative (-1.0)'
    """
    if not isinstance(row, dict) or not row:
        return "no row"
    if row.get("case") != str(case) or row.get("method") != str(method):
        return f"its row names another pair ({row.get('case')!r}, {row.get('method')!r})"
    if not isinstance(row.get("error"), str):
        return "its row has no error text"
    for k, v in row.items():
        bad = cell_problem(str(k), v)
        if bad:
            return bad
    if not row["error"] and not isinstance(row.get("time_s"), (int, float)) and row.get("time_reported") is not True:
        return "a successful row without time_s"  # a method computed elsewhere may have reported none
    return ""


def record_digest(rec: dict) -> str:
    """SHA-256 (hex) of a record's ``key``, ``case``, ``method``, ``row``, ``info`` and
    ``mesh``, and of those of :data:`RECORD_EXTRAS` it holds (canonical JSON): what
    :meth:`ResultStore.save` writes as ``digest``."""
    body = {k: rec.get(k) for k in ("key", "case", "method", "row", "info", "mesh")}
    body.update({k: rec[k] for k in RECORD_EXTRAS if k in rec})
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def output_digest(U) -> str:
    """SHA-256 (hex) of a result's deformed vertices ``U`` (n, 3) as float64 in C order,
    with their shape: two runs gave the same output exactly when their digests agree."""
    a = np.ascontiguousarray(U, dtype=np.float64)
    return hashlib.sha256(f"{a.shape}".encode() + a.tobytes()).hexdigest()


def _read_npy(p: Path, n: int | None) -> np.ndarray | None:
    """The (m, 3) float64 array of the regular ``.npy`` file ``p`` (opened without
    blocking, :func:`sshade.json_file.open_regular`), None when its header says another
    dtype or shape (``m`` = ``n`` when given) or the file holds other than the bytes it
    promises. OSError (a FIFO or a device included), ValueError."""
    with open_regular(p) as fh:
        st = os.fstat(fh.fileno())
        fmt = np.lib.format
        major = fmt.read_magic(fh)[0]
        if major not in (1, 2):
            return None
        shape, fortran, dtype = (fmt.read_array_header_1_0 if major == 1 else fmt.read_array_header_2_0)(fh)
        if dtype != np.dtype("<f8") or fortran or len(shape) != 2 or shape[1] != 3 or (n is not None and shape[0] != n):
            return None
        if st.st_size != fh.tell() + shape[0] * 24:
            return None
        return np.fromfile(fh, dtype="<f8", count=shape[0] * 3).reshape(shape)


class Lookup(NamedTuple):
    """What :meth:`ResultStore.lookup` found: ``record`` (the valid record, or None) and
    ``why`` (None when found; else ``"absent"``, or ``"other code: <what changed>"``,
    ``"other settings: <sections>"``, ``"invalid: <what is wrong>"``)."""
    record: dict | None
    why: str | None


def describe_change(old, new: dict) -> str:
    """In words, what differs between a stored record's code identity ``old`` (any JSON
    value: records written before code identities were keyed have none) and ``new``:
    e.g. ``"the project's sources changed"``, ``"numpy 1.26.4 -> 2.1.0"``, ``"the
    plug-in's source changed"``; ``""`` when they agree.

    >>> describe_change({"sources": "a", "versions": {"numpy": "1"}, "plugin": None},
    ...                 {"sources": "b", "versions": {"numpy": "2"}, "plugin": None})
    "the project's sources changed; numpy 1 -> 2"
    """
    if not isinstance(old, dict):
        return "a record without the identity of its code (written by an older version)"
    parts = []
    if old.get("sources") != new.get("sources"):
        parts.append("the project's sources changed")  # of the modules the row's code imports
    ref_old, ref_new = old.get("reference"), new.get("reference")
    if (ref_old or ref_new) and (ref_old or {}).get("sources") != (ref_new or {}).get("sources"):
        parts.append("the reference solver's code changed")
    ov, nv = old.get("versions") if isinstance(old.get("versions"), dict) else {}, new.get("versions") or {}
    parts += [f"{d} {ov.get(d)} -> {nv.get(d)}" for d in sorted(set(ov) | set(nv)) if ov.get(d) != nv.get(d)]
    if old.get("plugin") != new.get("plugin"):
        parts.append("the plug-in's source changed")
    return "; ".join(parts)


def _earlier_key(rec: dict, fields: dict | None) -> str | None:
    """The key of a record stored before :data:`LATER_CASE_FIELDS` were part of a case's
    identity, when ``rec`` is one (its case identity lacks them) and its key is that of
    ``fields`` (the pair's key fields now) without them: a record that agrees on all it
    holds; else None."""
    old = (rec.get("key_fields") or {}).get("case") if isinstance(rec.get("key_fields"), dict) else None
    if fields is None or not isinstance(old, dict) or any(k in old for k in LATER_CASE_FIELDS):
        return None
    case = {k: v for k, v in (fields.get("case") or {}).items() if k not in LATER_CASE_FIELDS}
    key = pair_key(fields.get("method"), case, fields.get("extra"), fields.get("code"))[0]
    return key if key == rec.get("key") else None


#: How a stale record's why begins when its code is current and its settings (method
#: definition, case data, guard or reference options) differ from the run's.
OTHER_SETTINGS = "other settings"


def _stale_why(old, new: dict | None) -> str:
    """Why a record under another key is stale: ``"other code: ..."`` when its code
    identity differs (:func:`describe_change`), else ``"other
    settings: <the differing sections>"``."""
    if new is None:
        return OTHER_SETTINGS
    old = old if isinstance(old, dict) else {}
    change = describe_change(old.get("code"), new.get("code") or {})
    if change:
        return f"other code: {change}"
    names = {"method": "method definition", "case": "case data", "extra": "guard or reference options"}
    diff = [w for k, w in names.items() if json_safe(old.get(k)) != new.get(k)]
    return f"{OTHER_SETTINGS}: {', '.join(diff) or 'key'}"


class ResultStore:
    """The store of one output folder (module docstring).

    Parameters
    ----------
    out_dir : the run's claimed output folder; the store is ``out_dir/runs``.
    meshes : bool, also store each successful run's deformed vertices (``.npy``).
    annotate : None or ``f(case, method, row) -> dict``, the :data:`RECORD_EXTRAS` a
        record gets besides its ``output`` digest (e.g. the reference it was scored
        against); other keys are left out.
    """

    def __init__(self, out_dir, *, meshes: bool = False, annotate=None):
        self.out_dir = Path(out_dir)
        self.root = self.out_dir / STORE_DIR
        self.meshes = bool(meshes)
        self.annotate = annotate
        self._git = None  # the checkout's state, read once at the first save
        self._machine = None  # the machine's, likewise

    def path(self, case: str, method: str) -> Path:
        """``runs/<case>/<method>.json`` (names through :func:`safe_name`), checked to lie
        inside the output folder with no link on the way (:func:`sshade.files.inside_folder`;
        SShaDeError otherwise)."""
        rel = Path(STORE_DIR) / safe_name(case) / f"{safe_name(method)}.json"
        return inside_folder(self.out_dir, rel, "result store")

    def check_links(self) -> None:
        """Refuse a store that reaches outside its folder: ``runs/`` or anything in it (a
        case folder, a record, a mesh) that is a symbolic link raises SShaDeError naming
        it, before a run reads or writes a record."""
        inside_folder(self.out_dir, STORE_DIR, "result store")
        if not self.root.is_dir():
            return
        for d in sorted(self.root.iterdir()):
            inside_folder(self.out_dir, d, "result store")
            if d.is_dir():
                for f in sorted(d.iterdir()):
                    inside_folder(self.out_dir, f, "result store")

    def load(self, case: str, method: str, key: str) -> dict | None:
        """The stored record of (``case``, ``method``) when its key is ``key`` and it is
        valid (:meth:`lookup`), else None."""
        return self.lookup(case, method, key).record

    def lookup(self, case: str, method: str, key: str, fields: dict | None = None) -> Lookup:
        """The stored record of (``case``, ``method``) under ``key``, read as untrusted
        input: :class:`Lookup` with the record when it is whole, of this store version,
        names that pair, matches its digest (:func:`record_digest`) and holds a valid row
        (:func:`check_row`), else None and why. ``fields``: the pair's key fields now
        (:func:`pair_key`), to say what differs in a stale record (code or settings)."""
        found = self.read(case, method, key=key)
        if found.record is None or found.why != "stale":
            return found
        earlier = _earlier_key(found.record, fields)
        if earlier is not None:
            return self.read(case, method, key=earlier)
        return Lookup(None, _stale_why(found.record.get("key_fields"), fields))

    def read(self, case: str, method: str, key: str | None = None) -> Lookup:
        """The record of (``case``, ``method``) read as untrusted input, whatever its key
        when ``key`` is None: as :meth:`lookup`, except that a record under another key
        than ``key`` comes back with ``why="stale"``."""
        p = self.path(case, method)
        if not p.is_file():
            return Lookup(None, "absent")
        try:
            rec = read_json(p)
        except (OSError, ValueError) as e:
            return Lookup(None, f"invalid: unreadable ({type(e).__name__})")
        if not isinstance(rec, dict):
            return Lookup(None, "invalid: not a record")
        if rec.get("version") != STORE_VERSION:
            return Lookup(None, f"other code: store version {rec.get('version')!r}, now {STORE_VERSION}")
        if rec.get("case") != str(case) or rec.get("method") != str(method):
            return Lookup(None, f"invalid: it names another pair ({rec.get('case')!r}, {rec.get('method')!r})")
        if key is not None and rec.get("key") != key:
            return Lookup(rec, "stale")
        if rec.get("digest") != record_digest(rec):
            return Lookup(None, "invalid: edited (its digest does not match)")
        if rec.get("key") != fields_digest(rec.get("key_fields")):
            return Lookup(None, "invalid: its key is not its key fields' digest (edited)")
        bad = check_row(rec.get("row"), case, method)
        if bad or not isinstance(rec.get("info"), dict):
            return Lookup(None, f"invalid: {bad or 'info is not a mapping'}")
        if rec.get("mesh") not in (None, self.path(case, method).with_suffix(".npy").name):
            return Lookup(None, "invalid: it names another mesh file")
        return Lookup(rec, None)

    def load_mesh(self, rec: dict, n: int) -> np.ndarray | None:
        """The deformed vertices (n, 3) float64 a record names, or None (not stored,
        unreadable, not a regular file, not a finite (n, 3) float64 ``.npy`` of the size
        its header gives, or not the output the record's ``output`` digest names: an
        edited mesh; ``n``: the case's vertex count, required so that a header promising
        another size is refused before any of it is read). Reads no more than ``n`` rows,
        and nothing of a FIFO or a device."""
        name = rec.get("mesh")
        if not name:
            return None
        try:
            p = inside_folder(self.out_dir, self.path(rec["case"], rec["method"]).with_name(str(name)), "result store")
            U = _read_npy(p, n)
        except (OSError, ValueError, EOFError, SShaDeError):
            return None
        ok = (U is not None and len(U) == n and bool(np.isfinite(U).all())
              and rec.get("output") in (None, output_digest(U)))
        return U if ok else None

    def save(self, case: str, method: str, key: str, fields: dict, row: dict, info=None, U=None,
             git: dict | None = None) -> Path:
        """Store one finished run atomically (the mesh first, then the record naming it,
        with the :func:`output_digest` of ``U`` (n, 3) when the run gave one, the fields
        ``annotate`` adds, and its :func:`record_digest`); ``git``: the checkout's state, recorded beside
        (default: :func:`eval.run.runinfo.git_info`, read once per store), as is the machine
        (:func:`eval.run.runinfo.machine_info`).
        Returns the record's path. OSError propagates (the caller decides)."""
        if git is None:
            if self._git is None:
                g = git_info()
                self._git = {"commit": g.get("commit"), "dirty": g.get("dirty")}
            git = self._git
        if self._machine is None:
            self._machine = machine_info()
        p = self.path(case, method)
        p.parent.mkdir(parents=True, exist_ok=True)
        mesh = None
        if self.meshes and U is not None:
            mesh = p.with_suffix(".npy").name
            with atomic_write(p.with_suffix(".npy"), "wb") as fh:
                np.save(fh, np.asarray(U, dtype=np.float64), allow_pickle=False)
        rec = {"version": STORE_VERSION, "case": str(case), "method": str(method), "key": key, "key_fields": fields,
               "row": json_safe(row), "info": json_safe(info or {}), "mesh": mesh, "git": json_safe(git),
               "machine": self._machine,
               "written_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
        if U is not None:
            rec["output"] = output_digest(U)
            rec.update(self._same_output(p, rec))
        extra = self.annotate(str(case), str(method), rec["row"]) if self.annotate is not None else None
        rec.update({k: json_safe(v) for k, v in (extra or {}).items() if k in RECORD_EXTRAS and k != "output"})
        rec["digest"] = record_digest(rec)
        with atomic_write(p, "w") as fh:
            fh.write(json.dumps(rec, indent=1) + "\n")
        alive(self.out_dir)  # the record is in place: the run's own, should it be killed
        return p

    def _same_output(self, p: Path, rec: dict) -> dict:
        """``{"same_output_as": {"commit", "key"}}`` when the record file ``p`` that ``rec``
        replaces (read as untrusted input: any unreadable or other content counts as none)
        is of another key and recorded the same ``output`` digest; else ``{}``."""
        try:
            old = read_json(p) if p.is_file() and not p.is_symlink() else None
        except (OSError, ValueError, RecursionError):
            old = None
        if not isinstance(old, dict) or old.get("output") != rec["output"] or old.get("key") == rec["key"]:
            return {}
        git = old.get("git") if isinstance(old.get("git"), dict) else {}
        commit = git.get("commit")
        log.info("%s %s: the same output bytes as its stored row of %s", rec["case"], rec["method"],
                 f"commit {str(commit)[:7]}" if commit else "no recorded commit")
        return {"same_output_as": {"commit": json_safe(git.get("commit")), "key": json_safe(old.get("key"))}}

    def rewrite(self, path, rec: dict) -> Path:
        """Write the record ``rec`` back over its file ``path`` (atomically), e.g. re-keyed
        (:func:`eval.run.stale_rows.rekey_record`). Raises SShaDeError when ``path`` is not
        this store's record of ``rec``'s case and method (:meth:`path`). Returns the path."""
        p = self.path(str(rec.get("case")), str(rec.get("method")))
        if Path(path).resolve() != p.resolve():
            raise SShaDeError(f"result store: {path} is not the record of ({rec.get('case')!r}, "
                              f"{rec.get('method')!r}) in {self.root}")
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
                rec = read_json(p)
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
