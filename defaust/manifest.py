"""The manifest of a DeFAUST build: its format, the out-folder check, item keys and
validity, and its atomic writing.

``manifest.json`` records the build's parameters, seeds and package versions, and per
*item* (``subject_XX/rest``, ``subject_XX/pose_YY``) its key (:func:`item_key`, a hash of
everything the item depends on) and its files' sha256. It is written with sorted keys
(deterministic bytes) and atomically (:func:`sshade.files.atomic_write`), after every
item of a build in progress (:func:`write_partial`). :func:`read_manifest_file` is the one
reader of the file's JSON and format (the builder's out-folder check and the loader).
"""
from __future__ import annotations

import hashlib
import json
import platform
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.json_file import read_json

from .store import sha256_file

__all__ = ["MANIFEST", "FORMAT", "BUILDER_VERSION", "ManifestError", "read_manifest_file", "check_out_folder",
           "write_manifest", "write_partial", "item_valid", "item_key", "distribution_versions",
           "package_versions"]

MANIFEST = "manifest.json"
FORMAT = "defaust-1"
#: Bumped whenever the builder's output for the same parameters changes. 2: the high-res
#: isotropic remesh without pymeshlab's per-collapse surface-distance check
#: (:func:`defaust.highres.subdivide_remesh`, ``check_distance``; the build twice as fast).
#: A change to one source's items only changes those items' keys instead, so the other
#: sources' builds stay valid: the faust pose items' ``high_ground_truth`` entry
#: (:data:`defaust.sources.FAUST_HIGH_GT`, the high-res ground truth of a FAUST build).
#: 3: every float of the ANNY and FAUST paths in a fixed order, machine-independent
#: (:mod:`defaust.fixed_order`, :mod:`defaust.anny_fixed`): the same bytes on every machine.
BUILDER_VERSION = 3


class ManifestError(SShaDeError):
    """A ``manifest.json`` that cannot be read or is not a DeFAUST manifest.

    Attributes
    ----------
    path : Path of the file. problem : ``"unreadable"`` or ``"format"``.
    detail : the read error's text, or the ``format`` found (None if there is none).

    ``str()`` is ``"<path> is unreadable (<error>)"`` or ``"<path> is not a DeFAUST
    manifest (format <found>)"``: callers prefix what they were doing.
    """

    def __init__(self, path, problem: str, detail):
        self.path, self.problem, self.detail = Path(path), problem, detail
        what = (f"is unreadable ({detail})" if problem == "unreadable"
                else f"is not a DeFAUST manifest (format {detail!r})")
        super().__init__(f"{self.path} {what}")


def read_manifest_file(path) -> dict:
    """The JSON of a DeFAUST ``manifest.json`` (format :data:`FORMAT`).

    Raises
    ------
    ManifestError (an SShaDeError) if the file is unreadable, not JSON, not an object or
    of another format.

    Examples
    --------
    Example::

        m = read_manifest_file("data/defaust/manifest.json")
        m["format"]
        # -> 'defaust-1'
    """
    try:
        m = read_json(path)
    except (ValueError, OSError) as e:
        raise ManifestError(path, "unreadable", e) from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise ManifestError(path, "format", m.get("format") if isinstance(m, dict) else None)
    return m


def distribution_versions(names) -> dict:
    """Installed version of each distribution in ``names`` (None when absent).

    Examples
    --------
    >>> sorted(distribution_versions(["numpy", "no-such-distribution"]))
    ['no-such-distribution', 'numpy']
    """
    out = {}
    for p in names:
        try:
            out[p] = version(p)
        except PackageNotFoundError:
            out[p] = None
    return out


def package_versions() -> dict:
    """Python's and the builder's packages' versions, as the manifest records them."""
    return {"python": platform.python_version(),
            **distribution_versions(("numpy", "scipy", "libigl", "pymeshlab", "numba", "trimesh", "hydra-core",
                                     "sshade"))}


def item_key(obj) -> str:
    """SHA-256 of the sorted-keys JSON of ``obj`` (everything an item depends on)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


#: Parameters that may change between two builds into one folder: building more (or
#: other) subjects extends a build, it does not contradict it.
_EXTENDABLE = ("subjects",)


def check_out_folder(out, source: str, parameters: dict) -> dict:
    """Refuse to build into a folder that holds something else; return its manifest.

    A build may write into ``out`` only when ``out`` does not exist, is empty, or holds
    a DeFAUST manifest of the same ``source`` and the same ``parameters`` (all but
    ``subjects``, which a later build may extend): an interrupted or partial build of
    the same dataset is resumed, anything else is left untouched. This protects a
    user's folder (e.g. a DeFAUST built from their FAUST scans) from being overwritten
    by a build with other settings.

    Parameters
    ----------
    out : str or Path, the output folder (need not exist).
    source : ``"anny"``, ``"faust"`` or ``"synthetic"``, the source of the build about to run.
    parameters : dict, :meth:`BuildConfig.parameters` of that build.

    Returns
    -------
    dict, the folder's manifest (empty for a new or empty folder).

    Raises
    ------
    SShaDeError
        ``out`` is not empty and has no ``manifest.json``; its manifest is unreadable or
        not a DeFAUST manifest; it names another source or other parameters (the
        message lists both values of every differing key and how to proceed).

    Examples
    --------
    Example::

        check_out_folder("/tmp/new_folder_xyz", "synthetic", {"seed": 0})
        # -> {}
    """
    out = Path(out)
    if not out.exists() or not any(out.iterdir()):
        return {}
    p = out / MANIFEST
    how = f"choose another out= folder (or, if {out} holds nothing you need, delete it first)"
    if not p.is_file():
        raise SShaDeError(f"refusing to build into {out}: the folder is not empty and holds no DeFAUST "
                          f"{MANIFEST}, so it was not made by this builder; {how}")
    try:
        m = read_manifest_file(p)
    except ManifestError as e:
        raise SShaDeError(f"refusing to build into {out}: {e}; {how}") from None
    old_src, old_par = m.get("source"), dict(m.get("parameters") or {})
    diff = []
    if old_src != source:  # the parameters of two sources differ anyway: name the source only
        diff.append(f"source: {old_src!r} there, {source!r} asked")
    for k in [] if diff else sorted(set(old_par) | set(parameters)):
        if k in _EXTENDABLE or k == "source":
            continue
        a, b = old_par.get(k), parameters.get(k)
        if json.dumps(a, sort_keys=True, default=str) != json.dumps(b, sort_keys=True, default=str):
            diff.append(f"{k}: {a!r} there, {b!r} asked")
    if diff:
        raise SShaDeError(f"refusing to build into {out}: it holds a DeFAUST build with other settings "
                          f"({'; '.join(diff)}). To evaluate that build: python -m eval dataset.root={out} "
                          f"(no build); to build these settings: {how}")
    return m


def write_manifest(out: Path, m: dict) -> None:
    """Write the manifest atomically (sorted keys: deterministic bytes); a no-op when
    the file already holds exactly this content."""
    m = dict(m)
    m["files"] = {f: h for it in m.get("items", {}).values() for f, h in it["files"].items()}
    text = json.dumps(m, indent=1, sort_keys=True) + "\n"
    p = out / MANIFEST
    if p.is_file() and p.read_text() == text:
        return
    with atomic_write(p, "w") as fh:
        fh.write(text)


def write_partial(out: Path, manifest: dict, old: dict) -> None:
    """Manifest of a build in progress: finished items so far plus the earlier build's
    entries (so an interruption loses nothing that was valid)."""
    write_manifest(out, {**manifest, "complete": False, "items": {**old.get("items", {}), **manifest["items"]},
                         "subjects": {**old.get("subjects", {}), **manifest["subjects"]}})


def partial_problem(m: dict, where) -> str | None:
    """The one line saying that manifest ``m`` (of the build at ``where``) is a build in
    progress or interrupted (``complete`` false: :func:`write_partial` wrote it), naming
    the subjects it lacks and how to finish it; None for a complete build (or one written
    before builds said so)."""
    if m.get("complete", True) is not False:
        return None
    done = {v.get("subject") for v in (m.get("subjects") or {}).values() if isinstance(v, dict)}
    planned = m.get("planned_subjects") if isinstance(m.get("planned_subjects"), list) else []
    missing = sorted(set(planned) - done, key=str)
    lacks = (f"subject(s) {', '.join(map(str, missing[:8]))}{' ...' if len(missing) > 8 else ''} of {len(planned)} "
             "not finished" if missing else "not finished")
    return (f"{where}: a partial DeFAUST build ({lacks}; {len(done)} complete): the build was interrupted or "
            "is still running. Run the command that built it again (it resumes: finished items are kept), or "
            "load the complete subjects only with defaust.load(..., partial=True)")


#: Subjects of a FAUST source (MPI-FAUST's registrations: 10 people).
FAUST_SUBJECTS = 10


def subset_words(m: dict) -> str | None:
    """What a build of some subjects only holds, in words, from manifest ``m``: its
    ``parameters.subjects`` (the builder's ``subjects=[...]``, extended by later builds into
    the folder) when they leave out some of the subjects a build without them makes (0 ..
    ``n_subjects`` - 1, or FAUST's 10); None for a build of every subject.

    >>> subset_words({"parameters": {"subjects": [0, 1], "n_subjects": 10}})
    'subject(s) 0, 1 (8 of its 10 not built)'
    >>> subset_words({"parameters": {"subjects": None, "n_subjects": 10}}) is None
    True
    """
    par = m.get("parameters") or {}
    held = par.get("subjects")
    if not isinstance(held, list):
        return None
    total = par.get("n_subjects") if isinstance(par.get("n_subjects"), int) else FAUST_SUBJECTS
    missing = set(range(total)) - {x for x in held if isinstance(x, int)}
    if not missing:
        return None
    shown = ", ".join(map(str, held[:8])) + (" ..." if len(held) > 8 else "")
    return f"subject(s) {shown} ({len(missing)} of its {total} not built)"


def subset_problem(m: dict, where) -> str | None:
    """The one line saying that manifest ``m`` (of the build at ``where``) holds some
    subjects only (:func:`subset_words`), how to load them and how to build the others;
    None for a build of every subject."""
    words = subset_words(m)
    if words is None:
        return None
    held = ",".join(map(str, m["parameters"]["subjects"]))
    return (f"{where}: a DeFAUST build of {words}, built with subjects=[{held}]: load those with "
            f"defaust.load(..., subjects=[{held}]) (the evaluator: dataset.subjects=[{held}]) or partial=True, or "
            "add the others by running its build command again without subjects (python -m defaust out=FOLDER)")


def item_valid(out: Path, entry: dict | None, key: str) -> bool:
    """Whether a manifest ``entry`` of an earlier build is this item, complete: the same
    ``key`` and every recorded file present with its recorded sha256."""
    if not entry or entry.get("key") != key or not entry.get("files"):
        return False
    return all(sha256_file(out / f) == h for f, h in entry["files"].items())


def _held(m: dict) -> set:
    """The subject ids manifest ``m`` holds (its ``subjects`` entries)."""
    return {v.get("subject") for v in (m.get("subjects") or {}).values()
            if isinstance(v, dict) and isinstance(v.get("subject"), int)}


def self_problems(m: dict, where) -> list[str]:
    """What manifest ``m`` (of the build at ``where``) says against itself, one line each:
    a complete build holding other subjects than its ``parameters.subjects`` (or, without
    them, the ``n_subjects`` a build makes; a FAUST build without them makes the subjects its
    folder holds, which only ``planned_subjects`` names) or its ``planned_subjects`` (a manifest with no
    ``parameters`` at all is not held to them: a source's own check names it); an item lacking a
    file that the other items of its kind (rest, pose) hold (a ground truth deleted with
    its entries, say)."""
    out, par = [], m.get("parameters") if isinstance(m.get("parameters"), dict) else None
    held = _held(m)
    if par is not None and m.get("complete", True) is not False:  # without parameters: nothing to hold it to
        claimed = par.get("subjects")
        total = par.get("n_subjects") if isinstance(par.get("n_subjects"), int) else FAUST_SUBJECTS
        want = {x for x in claimed if isinstance(x, int)} if isinstance(claimed, list) else set(range(total))
        if not isinstance(claimed, list) and par.get("source") == "faust":
            want = None  # the subjects its FAUST folder holds: only planned_subjects names them
        planned = m.get("planned_subjects")
        for what, ids in (("its parameters", want), ("its planned_subjects", set(planned) if isinstance(planned, list)
                                                      else held)):
            if ids is not None and held != ids:
                out.append(f"{where}: a complete build holding subject(s) {sorted(held)}, but {what} name "
                           f"{sorted(ids, key=str)}: an edited or cut manifest; rebuild it")
                break
    kinds: dict = {}
    for key, it in (m.get("items") or {}).items():
        if isinstance(it, dict) and isinstance(it.get("files"), dict):
            kind = "rest" if str(key).endswith("/rest") else "pose"
            kinds.setdefault(kind, []).append((key, {f[len(key):] for f in it["files"] if f.startswith(key)}))
    for kind, items in kinds.items():
        every = set().union(*(s for _, s in items))
        out += [f"{where}: item {key} lacks {', '.join(sorted(every - s))}, which every other {kind} item holds: a "
                "file removed with its entries? verify against the build's archive or rebuild it"
                for key, s in items if s != every]
    return out


def checked_manifest(m: dict, where) -> dict:
    """``m`` when it agrees with itself (:func:`self_problems`); SShaDeError naming its first problem."""
    bad = self_problems(m, where)
    if bad:
        raise SShaDeError(bad[0] + (f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""))
    return m
