"""``python -m sshade deform MESH -o OUT ...``: runs :func:`sshade.cli.main` (the argument
parsing, the handle-file readers of :mod:`sshade.mesh.handle_files` and the mesh I/O of
:mod:`sshade.mesh.io`). See :mod:`sshade.cli` for the options.
"""
from __future__ import annotations

import sys

from .cli import main as cli_main


def main() -> int:
    """Run :func:`sshade.cli.main` on the command line's arguments."""
    return cli_main(sys.argv[1:])


if __name__ == "__main__":
    sys.exit(main())
