"""Provenance of an evaluation run, written as ``run.json`` beside the tables.

Records: the resolved config, the departures from the paper that the config selects
(:func:`departures`, docs/differences.md), the seeds used (dataset seed, per-case handle seeds,
method seeds), the git commit of the project (and which tracked files had local
changes), the Python version, the platform and the machine (:func:`machine_info`: CPU model,
its widest SIMD set, cores), the versions of the packages in
:data:`PACKAGES` (numerical libraries, Hydra and its launchers, matplotlib) and, per
method, the source file of its class with its sha256 and git state
(:func:`method_sources`: a plug-in's code is identified even outside this repository).
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import inspect
import json
import os
import platform
import subprocess
import sys
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

from sshade.files import atomic_write
from sshade.json_file import read_json

__all__ = ["PACKAGES", "SIMD_LEVELS", "package_versions", "machine_info", "machine_words", "git_info", "method_sources",
           "read_runinfo", "effective_params", "source_record", "departures", "register_departures",
           "collect_runinfo", "write_runinfo"]

#: distribution name -> import name (for a fallback ``__version__``).
PACKAGES = {"numpy": "numpy", "scipy": "scipy", "libigl": "igl", "pymeshlab": "pymeshlab",
            "trimesh": "trimesh", "pandas": "pandas", "hydra-core": "hydra", "omegaconf": "omegaconf",
            "numba": "numba", "tqdm": "tqdm", "matplotlib": "matplotlib", "hydra-joblib-launcher": "hydra_plugins",
            "hydra-submitit-launcher": "hydra_plugins", "submitit": "submitit"}

REPO_ROOT = Path(__file__).resolve().parents[2]

#: CPU flags naming the SIMD sets vectorised kernels choose their code by, widest first
#: (x86's, then Arm's as /proc/cpuinfo spells them).
SIMD_LEVELS = ("avx512f", "avx2", "avx", "sse4_2", "sve", "asimd")
_CPUINFO = Path("/proc/cpuinfo")
_CPUINFO_MAX = 1 << 16


def machine_info(cpuinfo: Path = _CPUINFO) -> dict:
    """The machine a run computes on, recorded beside its results.

    Why: vectorised kernels (PyTorch's, a BLAS's) pick their code by the CPU's widest SIMD
    set, so one seeded computation can give other floats on another machine
    (docs/methods.md, Implicit-ARAP); the record says which machine made a row.

    Parameters
    ----------
    cpuinfo : the Linux CPU description to read (its first processor's block, at most
        64 kB); elsewhere, or unreadable, the CPU is ``platform.processor()``.

    Returns
    -------
    dict ``{"cpu": model name or None, "simd": the first of SIMD_LEVELS its flags name
    or None, "cores": os.cpu_count()}``. Never raises.
    """
    fields: dict[str, str] = {}
    try:
        with open(cpuinfo, "rb") as fh:
            text = fh.read(_CPUINFO_MAX).decode("utf-8", "replace")
    except OSError:
        text = ""
    for line in text.splitlines():
        if not line.strip():
            if fields:
                break
            continue
        key, _, value = line.partition(":")
        fields.setdefault(key.strip().lower(), value.strip())
    flags = set((fields.get("flags") or fields.get("features") or "").split())
    cpu = fields.get("model name") or fields.get("cpu model") or platform.processor() or None
    simd = next((s for s in SIMD_LEVELS if s in flags), None)
    return {"cpu": cpu, "simd": simd, "cores": os.cpu_count()}


def machine_words(m) -> str | None:
    """A machine of :func:`machine_info` in words, the same for two records of one machine:
    ``"AMD EPYC, avx2, 2 cores"``; None for anything without a CPU name (an older record).

    >>> machine_words({"cpu": "AMD EPYC", "simd": "avx2", "cores": 2}), machine_words(None)
    ('AMD EPYC, avx2, 2 cores', None)
    """
    if not isinstance(m, dict) or not isinstance(m.get("cpu"), str) or not m["cpu"].strip():
        return None
    return f"{m['cpu'].strip()}, {m.get('simd') or 'simd unknown'}, {m.get('cores')} cores"


def package_versions() -> dict[str, str | None]:
    """Installed version of each package in :data:`PACKAGES` (None when absent)."""
    out: dict[str, str | None] = {}
    for dist, mod in PACKAGES.items():
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            try:
                out[dist] = str(getattr(__import__(mod), "__version__", None))
            except Exception:
                out[dist] = None
    return out


def git_info(root=REPO_ROOT) -> dict:
    """The git state of the checkout at ``root``.

    Returns
    -------
    dict ``{"commit": sha or None, "dirty": bool or None, "modified": [paths]}``:
    ``dirty`` is True when a tracked file differs from the commit (staged or not);
    ``modified`` names those files (relative to the repository root). Untracked files
    (e.g. a run's own output folder) and the committed results under ``results/`` (what
    runs write, not code) do not make a checkout dirty. All None/empty outside a git
    checkout or without git.
    """
    def git(*args):
        r = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=10)
        return r.stdout if r.returncode == 0 else None
    try:
        sha = git("rev-parse", "HEAD")
        status = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)results") if sha else None
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None, "modified": []}
    if status is None:
        return {"commit": sha.strip() if sha else None, "dirty": None, "modified": []}
    modified = [line[3:].strip() for line in status.splitlines() if line.strip()]
    return {"commit": sha.strip(), "dirty": bool(modified), "modified": modified}


def _git_file_state(path: Path) -> dict | None:
    """``{"work_tree", "tracked", "dirty"}`` of ``path`` in the git work tree holding it,
    None outside one (or without git). ``dirty``: tracked and differing from HEAD
    (staged or not); an untracked or ignored file is ``tracked: false``."""
    def git(*args):
        r = subprocess.run(["git", "-C", str(path.parent), *args], capture_output=True, text=True, timeout=10)
        return r.stdout if r.returncode == 0 else None
    try:
        top = git("rev-parse", "--show-toplevel")
        st = git("status", "--porcelain", "--ignored", "--", path.name) if top else None
    except (OSError, subprocess.SubprocessError):
        return None
    if top is None or st is None:
        return None
    code = st[:2] if st.strip() else ""
    tracked = code not in ("??", "!!")
    return {"work_tree": top.strip(), "tracked": tracked, "dirty": bool(code) and tracked}


def source_record(path) -> dict:
    """What identifies one source file: ``file`` (absolute), ``sha256`` of its bytes,
    ``in_repo`` (inside this checkout), ``git`` (:func:`_git_file_state`, None outside a
    work tree). An unreadable file gets ``sha256: None``."""
    p = Path(path).resolve()
    try:
        digest = hashlib.sha256(p.read_bytes()).hexdigest()
    except OSError:
        digest = None
    return {"file": str(p), "sha256": digest, "in_repo": p.is_relative_to(REPO_ROOT),
            "git": _git_file_state(p)}


def method_sources(methods) -> list[dict]:
    """Per method (objects with a ``name``), the source of its class: ``name``, ``class``
    (``module.QualName``), ``params`` (:func:`effective_params`) and :func:`source_record`
    of the module's file (``file: None`` for a class without a Python file). Built-in
    methods too: one rule for all."""
    out, seen = [], {}
    for m in methods:
        cls = type(m)
        rec = {"name": str(getattr(m, "name", cls.__name__)), "class": f"{cls.__module__}.{cls.__qualname__}",
               "params": effective_params(m)}
        try:
            f = inspect.getsourcefile(cls) or inspect.getfile(cls)
        except (TypeError, OSError):
            f = None
        if f is None:
            rec.update(file=None, sha256=None, in_repo=False, git=None)
        else:
            if f not in seen:
                seen[f] = source_record(f)
            rec.update(seen[f])
        out.append(rec)
    return out


def read_runinfo(folder) -> dict:
    """The ``run.json`` of run folder ``folder`` as a dict; ``{}`` when it is missing,
    unreadable, not JSON or not a mapping (a folder's record read as untrusted input)."""
    try:
        info = read_json(Path(folder) / "run.json")
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def effective_params(method) -> dict | None:
    """The parameters ``method`` runs with, every default and preset value resolved, as
    its ``effective_params()`` reports them (each built-in method has one: e.g.
    :meth:`sshade.SShaDe.effective_params`), as JSON values; None for a method without
    one (a plug-in: its config mapping is in ``run.json``'s config) or whose report fails."""
    fn = getattr(method, "effective_params", None)
    if not callable(fn):
        return None
    try:
        return json.loads(json.dumps(fn(), default=str, allow_nan=False))
    except Exception:  # noqa: BLE001 -- a plug-in's report: never fails the run
        return None


#: method option -> (the paper's value, short reason); docs/differences.md explains each.
_PAPER_METHOD_OPTIONS = {
    "gradient": ("raw", "orthonormalised LRF instead of the raw gradient frame of §3.2 eq. (2)"),
    "anchor": ("barycenter", "each vertex anchored at its projection onto its triangle, not at the barycenter "
                             "of Alg. 1"),
    "warm_start": (False, "samplings 1..k-1 start from sampling 0's result (§3.3: independent)"),
    "protocol": ("paper", "ARAP run to the converged criterion, not the 1000-iteration move rule of §4.1"),
    "energy": ("spokes_and_rims", "another low-resolution ARAP energy than the spokes and rims of §4.1"),
    "transfer": ("triangle", "the corners' deformation gradients blended across each low-res triangle, not one "
                             "frame per triangle (Alg. 1)"),
    "average": ("uniform", "the samplings weighted per vertex, not the plain mean of §3.3"),
}


def departures(resolved: dict) -> list[str]:
    """Departures from the paper selected by a resolved config (docs/differences.md).

    Parameters
    ----------
    resolved : the resolved config as plain containers. Read: ``methods`` and their
        ``method.<name>`` sections (``gradient``, ``anchor``, ``warm_start``, ``protocol``,
        ``energy``), else the ``sshade`` / ``arap`` sections; the ``dataset`` section by
        its dataset's own rule (:func:`register_departures`, e.g. FAUST's protocol).

    Returns
    -------
    list of short strings ``"<where>.<key>=<value> (paper: <value>): <why>"``, one per
    switch at a non-paper value, in a fixed order; empty when every switch has the
    paper's value. Departures without a switch (docs/differences.md) are not listed.

    Examples
    --------
    >>> departures({"sshade": {"gradient": "raw", "warm_start": False}, "arap": {"protocol": "paper"}})
    []
    >>> departures({"arap": {"protocol": "converged"}})[0].split(":")[0]
    'arap.protocol=converged (paper'
    """
    out: list[str] = []
    sections = resolved.get("method") or {}
    names = [n for n in (resolved.get("methods") or []) if isinstance(n, str) and isinstance(sections.get(n), dict)]
    where = {f"method.{n}": sections[n] for n in names} or {
        "sshade": resolved.get("sshade") or {}, "arap": resolved.get("arap") or {}}
    for prefix, sec in where.items():
        for key, (paper, why) in _PAPER_METHOD_OPTIONS.items():
            if key in sec and sec[key] is not None and sec[key] != paper:
                out.append(f"{prefix}.{key}={_fmt(sec[key])} (paper: {_fmt(paper)}): {why}")
    ds = resolved.get("dataset") or {}
    rule = _DATASET_DEPARTURES.get(str(ds.get("name", "")))
    return out + (list(rule(ds)) if rule is not None else [])


#: dataset name -> ``rule(section) -> [line]``: the departures its section selects, each
#: registered by the dataset's own module (:func:`register_departures`).
_DATASET_DEPARTURES: dict[str, Callable] = {}


def register_departures(dataset: str, rule: Callable) -> Callable:
    """Register ``rule(section) -> list[str]``, the departures from the paper that dataset
    ``dataset``'s config section (plain values) selects, in :func:`departures`' form;
    called by the dataset's own module. Returns ``rule``."""
    _DATASET_DEPARTURES[str(dataset)] = rule
    return rule


def _fmt(v) -> str:
    """A config value as written on the command line (true/false for bools)."""
    return str(v).lower() if isinstance(v, bool) else str(v)


def collect_runinfo(resolved: dict, *, seeds: dict | None = None, extra: dict | None = None) -> dict:
    """Provenance dict (JSON-serialisable).

    Parameters
    ----------
    resolved : the resolved config as plain containers (:meth:`eval.run.spec.EvalSpec.record`),
        recorded as ``config``.
    seeds : seeds used, e.g. ``{"dataset": 0, "sshade": 0, "cases": {"s0_p1": 123}}``.
    extra : anything else to record (status, timings, output paths).
    """
    info = {
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": _command(),
        "cwd": os.getcwd(),
        "config": resolved,
        "departures": departures(resolved),
        "seeds": seeds or {},
        "git": git_info(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "machine": machine_info(),
        "packages": package_versions(),
    }
    if extra:
        info.update(extra)
    return info


def write_runinfo(path, info: dict) -> Path:
    """Write ``info`` as indented JSON to ``path`` atomically; returns the path."""
    path = Path(path)
    with atomic_write(path, "w") as fh:
        json.dump(info, fh, indent=2, sort_keys=False, default=_jsonable)
        fh.write("\n")
    return path


def _command() -> list[str]:
    """The command line, with ``python -m eval`` instead of the path of ``__main__.py``."""
    prog = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
    head = ["python", "-m", prog.parent.name] if prog.name == "__main__.py" else [prog.name]
    return [*head, *sys.argv[1:]]


def _jsonable(o):
    """Fallback for numpy scalars/arrays and paths."""
    if hasattr(o, "tolist"):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    return repr(o)


def finish_run(out_dir, md: str, paths: dict, info: dict, *, n_cases: int, n_errors: int, wall_s: float) -> None:
    """End of an experiment run: write ``table.md`` (atomically), mark ``run.json`` done
    with the counts and the output names, print the table and the written files.
    ``paths`` (name -> Path) gains ``table_md`` and ``run_json``."""
    out_dir = Path(out_dir)
    with atomic_write(out_dir / "table.md", "w") as fh:
        fh.write(md)
    paths["table_md"] = out_dir / "table.md"
    info.update(status="done", n_cases=n_cases, n_errors=n_errors, wall_s=round(wall_s, 3),
                outputs={key: Path(v).name for key, v in paths.items()})
    paths["run_json"] = write_runinfo(out_dir / "run.json", info)
    print(md)
    print(f"wrote {', '.join(Path(v).name for v in paths.values())} to {out_dir}")
