"""The canonical DeFAUST: the checksums of the builds everyone compares on, committed with
the code (``defaust/canonical/<name>.json``: per item of the build, its key and its files'
sha256), and a build held against them (:func:`canonical_status`). A build is canonical
when every item it holds is an item of one canonical build, under the same item key (the
same builder version, source, seed, parameters, assets and ANNY versions), with the same
bytes; a build of some of its subjects is canonical for those. ``python -m defaust verify
DIR`` says which (``--canonical``: exit 1 when not); ``python -m defaust.canonical DIR
NAME`` writes a record from a build (a maintainer's step, after a change of the
builder's bytes). Why it matters: docs/defaust.md §7, "Is it the canonical DeFAUST?".
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

from harness.command import run_command
from sshade.command_errors import ArgumentParser
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.json_file import read_json

from .dataset import read_manifest, verify

__all__ = ["CANONICAL_DIR", "CanonicalStatus", "canonical_records", "canonical_record", "canonical_status", "main"]

#: Where the canonical records live (one JSON file per canonical build).
CANONICAL_DIR = Path(__file__).with_name("canonical")


@dataclass(frozen=True)
class CanonicalStatus:
    """A build held against the canonical records.

    Attributes
    ----------
    canonical : bool, every item held is a canonical build's, byte for byte.
    name : str or None, that canonical build's name (the one holding the first item).
    items : int, items of the build checked. of : int, items of that canonical build.
    difference : str or None, the first item or file that differs, in words.
    unrecorded : int, items of a build of a canonical record's kind (builder version, source,
        ANNY versions and parameters but the subjects and the FAUST folder) whose item the
        record does not hold (a FAUST subject it lacks): nobody's bytes to hold them to.
    """
    canonical: bool
    name: str | None
    items: int
    of: int
    difference: str | None
    unrecorded: int = 0

    def words(self) -> str:
        """One line for a person: what the build is, and what follows for comparisons."""
        if self.unrecorded and self.difference and self.difference.startswith(_UNRECORDED):
            return (f"{self.difference}. Its other {self.items - self.unrecorded} items are the canonical "
                    f"'{self.name}' build's; rows on the unrecorded ones compare only with rows made on this build")
        if self.canonical:
            part = "" if self.items == self.of else f" ({self.items} of its {self.of} items)"
            return f"the canonical DeFAUST '{self.name}'{part}: rows made on it compare with anyone's rows on it"
        return (f"not the canonical DeFAUST: {self.difference}. Rows made on this build compare only with rows "
                "made on this same build, not with rows made on the canonical one (other meshes or handles)")


def canonical_records(folder=None) -> dict[str, dict]:
    """The canonical records, by name (the file's stem), read from ``folder`` (default
    :data:`CANONICAL_DIR`). Raises SShaDeError on a record that is unreadable or not of
    the form :func:`canonical_record` writes."""
    out = {}
    for p in sorted(Path(folder or CANONICAL_DIR).glob("*.json")):
        try:
            rec = read_json(p)
        except (OSError, ValueError) as e:
            raise SShaDeError(f"{p}: unreadable canonical record ({e})") from None
        items = rec.get("items") if isinstance(rec, dict) else None
        if not isinstance(items, dict) or not all(_item_ok(v) for v in items.values()):
            raise SShaDeError(f"{p}: not a canonical record (items with a key and their files' sha256)")
        out[p.stem] = rec
    return out


def _item_ok(v) -> bool:
    """Whether ``v`` is an item of a canonical record: a key and a ``{file: sha256}`` map."""
    return (isinstance(v, dict) and isinstance(v.get("key"), str) and isinstance(v.get("files"), dict)
            and all(isinstance(k, str) and isinstance(h, str) for k, h in v["files"].items()))


def canonical_record(manifest: dict) -> dict:
    """The canonical record of a build from its manifest (read by
    :func:`defaust.dataset.read_manifest`, the build verified): its format, builder
    version, source and parameters (what it was built with, for a reader; not the FAUST
    folder, a machine's path), and per item its key and its files' sha256. Raises
    SShaDeError on a partial build."""
    if not manifest.get("complete"):
        raise SShaDeError("a canonical record is made from a complete build (this one is partial)")
    items = {i: {"key": v["key"], "files": dict(sorted(v["files"].items()))}
             for i, v in sorted(manifest.get("items", {}).items())}
    keep = ("format", "builder_version", "source", "parameters", "anny")
    rec = {k: manifest[k] for k in keep if k in manifest}
    if isinstance(rec.get("parameters"), dict):  # a machine's folder is no part of what the build is
        rec["parameters"] = {k: v for k, v in rec["parameters"].items() if k != "faust_root"}
    return {**rec, "items": items}


def canonical_status(manifest: dict, records: dict | None = None) -> CanonicalStatus:
    """Hold a build's manifest against the canonical records.

    Parameters
    ----------
    manifest : dict, the build's ``manifest.json`` (its files already verified against it:
        :func:`defaust.dataset.verify`). records : {name: record} or None
        (:func:`canonical_records`).

    Returns
    -------
    CanonicalStatus: canonical when every item's key is an item of one canonical record
    with the same files; otherwise the first item (in sorted order) that is no canonical
    item, or its first file whose sha256 differs.
    """
    records = canonical_records() if records is None else records
    by_key = {v["key"]: (name, i, v) for name, rec in records.items() for i, v in rec["items"].items()}
    items = manifest.get("items") if isinstance(manifest.get("items"), dict) else {}
    kind = next((n for n, rec in records.items() if _kind(rec) == _kind(manifest)), None)
    name, unrecorded = None, []
    for i, v in sorted(items.items()):
        hit = by_key.get(v.get("key")) if isinstance(v, dict) else None
        if hit is None and kind is not None and i not in records[kind]["items"]:
            unrecorded.append(i)  # of the record's kind, an item it does not hold
            continue
        if hit is None:
            return CanonicalStatus(False, None, len(items), 0, f"its item {i} is no item of a canonical build "
                                   "(other builder version, source, seed, parameters, assets or ANNY versions)")
        name = name or hit[0]
        files = v.get("files") if isinstance(v.get("files"), dict) else {}
        for rel in sorted(set(files) | set(hit[2]["files"])):
            mine, theirs = files.get(rel), hit[2]["files"].get(rel)
            if mine != theirs:
                return CanonicalStatus(False, hit[0], len(items), len(records[hit[0]]["items"]),
                                       f"{rel} differs from the canonical '{hit[0]}' build's (sha256 "
                                       f"{str(mine)[:12]}... here, {str(theirs)[:12]}... there)")
    if unrecorded:
        name = name or kind
        return CanonicalStatus(False, name, len(items), len(records[name]["items"]),
                               f"{_UNRECORDED} {len(unrecorded)} of its items ({unrecorded[0]} first): the "
                               f"canonical '{name}' record holds {len(records[name]['items'])} items of this kind",
                               len(unrecorded))
    of = len(records[name]["items"]) if name else 0
    return CanonicalStatus(bool(items), name, len(items), of, None if items else "it holds no item")


#: How the difference of a build with items no canonical record holds begins.
_UNRECORDED = "no canonical record holds"
#: The parameters that say where or which part of a build, not what its items are.
_LOCAL_PARAMETERS = ("subjects", "n_subjects", "faust_root")


def _kind(d: dict) -> str:
    """What a build or record is a build of, as JSON: builder version, source, ANNY versions
    and parameters but :data:`_LOCAL_PARAMETERS` (the items a record could hold)."""
    params = d.get("parameters") if isinstance(d.get("parameters"), dict) else {}
    return json.dumps([d.get("builder_version"), d.get("source"), d.get("anny"),
                       {k: v for k, v in params.items() if k not in _LOCAL_PARAMETERS}], sort_keys=True)


def _write(root: str, name: str) -> int:
    """Write ``CANONICAL_DIR / f"{name}.json"`` from the build ``root`` (:func:`main`)."""
    problems = verify(root)
    if problems:
        raise SShaDeError(f"{root} does not verify ({problems[0]})")
    rec = canonical_record(read_manifest(root))
    CANONICAL_DIR.mkdir(exist_ok=True)
    with atomic_write(CANONICAL_DIR / f"{name}.json", "w") as fh:
        fh.write(json.dumps(rec, indent=1, sort_keys=True) + "\n")
    print(f"wrote {CANONICAL_DIR / (name + '.json')}: {len(rec['items'])} items")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m defaust.canonical DIR NAME``: write ``defaust/canonical/NAME.json`` from
    the complete, verified build DIR; a refused build or name is one ``error:`` line and
    exit 2."""
    p = ArgumentParser(prog="python -m defaust.canonical",
                       description="Write the canonical record of a complete, verified DeFAUST build.")
    p.add_argument("root", help="the build folder (complete; python -m defaust verify passes)")
    p.add_argument("name", help="the record's name (letters, digits, - and _), e.g. anny-default")
    a = p.parse_args(sys.argv[1:] if argv is None else argv)
    if not a.name.replace("-", "").replace("_", "").isalnum():
        p.error(f"the name {a.name!r} must be letters, digits, - and _")
    return run_command(lambda: _write(a.root, a.name), where=a.root)


if __name__ == "__main__":
    sys.exit(main())
