"""``python -m defaust verify|describe|export DIR ...``: the command line of a built
dataset (the builder's own is :mod:`defaust.cli`).

- ``verify DIR``: every file against ``DIR/manifest.json`` (:func:`defaust.dataset.verify`);
  one line per problem on stdout, exit 0 for a good copy, 2 on any problem.
- ``describe DIR [--resolution high|low]``: one Markdown table row per case on stdout
  (:func:`defaust.describe.describe`: handles, the ground truth's volume and area change);
  writes nothing.
- ``export DIR --to FOLDER [--format npz|obj|ply] [--resolution high|low]
  [--subjects 0 1 ...]``: :func:`defaust.export.export`; a refused folder or a bad build
  is one ``error:`` line and exit 2, before any file is written.

Example::

    python -m defaust verify data/defaust
    python -m defaust describe data/defaust
    python -m defaust export data/defaust --to /tmp/defaust_obj --format obj --resolution low
"""
from __future__ import annotations

from harness.command import run_command
from sshade.clirun import ArgumentParser

from .dataset import RESOLUTIONS, verify
from .describe import describe, markdown
from .export import FORMATS, export

__all__ = ["COMMANDS", "main"]

#: The first words that select this command line instead of the builder's.
COMMANDS = ("verify", "describe", "export")


def _parser() -> ArgumentParser:
    p = ArgumentParser(prog="python -m defaust", description="Check or export a built DeFAUST dataset.")
    sub = p.add_subparsers(dest="command", required=True)
    v = sub.add_parser("verify", help="check every file of a build against its manifest")
    v.add_argument("root", help="the build folder (out= of the build)")
    d = sub.add_parser("describe", help="each case's handles and its ground truth's volume and area change")
    d.add_argument("root", help="the build folder")
    d.add_argument("--resolution", default="high", choices=RESOLUTIONS)
    e = sub.add_parser("export", help="write the cases for other tools (npz, or meshes + handle JSON)")
    e.add_argument("root", help="the build folder")
    e.add_argument("--to", required=True, help="export folder: new, empty, or an earlier export")
    e.add_argument("--format", default="npz", choices=FORMATS)
    e.add_argument("--resolution", default="high", choices=RESOLUTIONS)
    e.add_argument("--subjects", type=int, nargs="+", default=None)
    return p


def _verify(root) -> int:
    problems = verify(root)
    for line in problems:
        print(line)
    if problems:
        print(f"{len(problems)} problem(s) in {root}")
        return 2
    print(f"{root}: every file matches its manifest")
    return 0


def _export(a) -> int:
    files = export(a.root, a.to, fmt=a.format, resolution=a.resolution, subjects=a.subjects)
    size = sum(f.stat().st_size for f in files)
    print(f"exported {len(files) - 1} file(s) ({size / 2**20:.1f} MiB) to {a.to}")
    return 0


def main(argv: list[str]) -> int:
    """Run ``verify``, ``describe`` or ``export`` with ``argv`` (the words after ``python -m defaust``);
    returns the exit status (a bad command line: one ``error:`` line, exit 2)."""
    a = _parser().parse_args(argv)
    if a.command == "verify":
        return run_command(lambda: _verify(a.root), where=a.root)
    if a.command == "describe":
        return run_command(lambda: print(markdown(describe(a.root, resolution=a.resolution)), end=""), where=a.root)
    return run_command(lambda: _export(a), where=a.to)
