"""``python -m sshade deform MESH -o OUT ...``: a thin shim. The argument parsing, the
handle-file readers and the mesh I/O live in :mod:`eval.deform_cli` (file formats stay
out of the geometry core); this module only calls it. See that module for the options.
"""
from __future__ import annotations

import sys


def main() -> int:
    """Run :func:`eval.deform_cli.main` on the command line's arguments."""
    from eval.deform_cli import main as cli_main
    return cli_main(sys.argv[1:])


if __name__ == "__main__":
    sys.exit(main())
