"""``python -m defaust verify|describe|export|pack DIR ...``: the command line of a built
dataset (the builder's own is :mod:`defaust.cli`). DIR is a build folder or, for
``verify``, ``describe`` and ``export``, an archive that ``pack`` wrote (read in place).
``verify`` (:func:`defaust.dataset.verify`: one line per problem, exit 0 for a good copy,
2 on any problem; then whether it is the canonical DeFAUST, :mod:`defaust.canonical`: exit 1
when not and ``--canonical`` is given), ``describe`` (:func:`defaust.describe.describe`:
one Markdown row per case, writes nothing), ``export`` (:func:`defaust.export.export`) and ``pack``
(:func:`defaust.packing.pack`); a refused folder, output or build is one ``error:`` line
and exit 2, before any file is written. Options: ``python -m defaust --help``; usage:
docs/defaust.md §6 and §7.
"""
from __future__ import annotations

from harness.command import run_command
from sshade.command_errors import ArgumentParser

from .canonical import canonical_status
from .dataset import read_manifest, verify
from .describe import describe, markdown
from .export import FORMATS, export
from .manifest import subset_words
from .packing import pack

__all__ = ["COMMANDS", "main"]

#: The first words that select this command line instead of the builder's.
COMMANDS = ("verify", "describe", "export", "pack")


def _parser() -> ArgumentParser:
    p = ArgumentParser(prog="python -m defaust", description="Check or export a built DeFAUST dataset.")
    sub = p.add_subparsers(dest="command", required=True)
    v = sub.add_parser("verify", help="check every file of a build against its manifest")
    v.add_argument("root", help="the build folder (out= of the build) or an archive that pack wrote")
    v.add_argument("--canonical", action="store_true",
                   help="exit 1 when the build is not (a part of) the canonical DeFAUST (it says so either way)")
    d = sub.add_parser("describe", help="each case's handles and its ground truth's volume and area change")
    d.add_argument("root", help="the build folder or archive")
    d.add_argument("--resolution", default="high", help="high, low or rN (an extra resolution the build has)")
    e = sub.add_parser("export", help="write the cases for other tools (npz, or meshes + handle JSON)")
    e.add_argument("root", help="the build folder or archive")
    e.add_argument("--to", required=True, help="export folder: new, empty, or an earlier export")
    e.add_argument("--format", default="npz", choices=FORMATS)
    e.add_argument("--resolution", default="high", help="high, low or rN (an extra resolution the build has)")
    e.add_argument("--subjects", type=int, nargs="+", default=None)
    k = sub.add_parser("pack", help="one zip archive of a build, with its manifest, Croissant file and datasheet")
    k.add_argument("root", help="the build folder")
    k.add_argument("-o", "--out", required=True, help="the archive to write (.zip): new, or an earlier pack")
    k.add_argument("--force", action="store_true", help="replace an existing file that pack did not write")
    return p


def _verify(root, canonical: bool = False) -> int:
    problems = verify(root)
    for line in problems:
        print(line)
    if problems:
        print(f"{len(problems)} problem(s) in {root}")
        return 2
    m = read_manifest(root)
    words = subset_words(m)
    print(f"{root}: every file matches its manifest" + (f"; a build of {words}" if words else ""))
    status = canonical_status(m)
    print(f"{root}: {status.words()}")
    return 1 if canonical and not status.canonical else 0


def _export(a) -> int:
    files = export(a.root, a.to, fmt=a.format, resolution=a.resolution, subjects=a.subjects)
    size = sum(f.stat().st_size for f in files)
    print(f"exported {len(files) - 1} file(s) ({size / 2**20:.1f} MiB) to {a.to}")
    return 0


def _pack(a) -> int:
    info = pack(a.root, a.out, force=a.force)
    print(f"packed {info['files']} file(s) ({info['bytes'] / 2**20:.1f} MiB) into {info['path']} "
          f"(folder {info['folder']}/, sha256 {info['sha256']})")
    return 0


def main(argv: list[str]) -> int:
    """Run ``verify``, ``describe``, ``export`` or ``pack`` with ``argv`` (the words after
    ``python -m defaust``); returns the exit status (a bad command line: one ``error:``
    line, exit 2)."""
    a = _parser().parse_args(argv)
    if a.command == "verify":
        return run_command(lambda: _verify(a.root, a.canonical), where=a.root)
    if a.command == "describe":
        return run_command(lambda: print(markdown(describe(a.root, resolution=a.resolution)), end=""), where=a.root)
    if a.command == "pack":
        return run_command(lambda: _pack(a), where=a.out)
    return run_command(lambda: _export(a), where=a.to)
