"""``python -m harness deform MESH -o OUT ...``: ``python -m sshade deform`` with every
method of the harness: the built-in ones by name (``ARAP``, ``Elastic``, ``ARAP-SR``,
``Implicit-ARAP``, ``SShaDe``, ``SShaDe+refine``: :func:`harness.method_registry.builtin_methods`,
their definitions in ``conf/method/``, the defaults of ``conf/config.yaml``) and a plug-in
``pkg.module.Class`` (:func:`harness.method_registry.named_or_plugin`). The options, handle
files, checks and outputs are those of :mod:`sshade.deform_command`.

Example::

    python -m harness deform bar.off --sel bar.sel --def bar.def --method ARAP -o out.obj
"""
from __future__ import annotations

import sys

from harness.command import run_command
from harness.method_registry import named_or_plugin
from sshade.deform_command import deform_main

__all__ = ["main"]

USAGE = ("usage: python -m harness deform MESH -o OUT (--sel F.sel --def F.def | --dmat F.dmat --def F.def | "
         "--handles F.json|F.csv) [--method NAME|pkg.module.Class] [--n-low N] [--k K] [--seed S] "
         "[--param KEY=VALUE] [--timeout SECONDS] [--repair] [--force]\n(python -m harness deform --help for details)")


def main(argv=None) -> int:
    """Entry point of ``python -m harness``; returns the exit status (0 success, 2 bad input
    or usage after one ``error:`` line, 130/143 interrupted)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE, file=sys.stderr if not argv else sys.stdout)
        return 2 if not argv else 0
    if argv[0] != "deform":
        print(f"error: unknown command {argv[0]!r}; the command is `python -m harness deform MESH -o OUT ...`",
              file=sys.stderr)
        return 2
    return deform_main(argv[1:], prog="python -m harness", resolve=named_or_plugin, run=run_command)


if __name__ == "__main__":
    sys.exit(main())
