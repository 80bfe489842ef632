"""``python -m sshade deform MESH -o OUT ...``: runs :func:`sshade.deform_command.main` (the argument
parsing, the handle-file readers of :mod:`sshade.mesh.handle_files` and the mesh I/O of
:mod:`sshade.mesh.io`). See :mod:`sshade.deform_command` for the options.
"""
from __future__ import annotations

import sys

from .numba_cache import ensure_cache

ensure_cache()  # before the first kernel module: a command runs where numba cannot cache

from .deform_command import main as cli_main  # noqa: E402


def main() -> int:
    """Run :func:`sshade.deform_command.main` on the command line's arguments."""
    return cli_main(sys.argv[1:])


if __name__ == "__main__":
    sys.exit(main())
