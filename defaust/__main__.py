"""``python -m defaust [overrides]``: build a DeFAUST dataset (see :mod:`defaust.cli`);
``python -m defaust verify|describe|export|pack ...``: check, describe, export or pack a build
(:mod:`defaust.dataset_cli`)."""
import sys

from sshade.numba_cache import ensure_cache

ensure_cache()  # before the first kernel module: a command runs where numba cannot cache

if __name__ == "__main__":
    from .dataset_cli import COMMANDS
    from .dataset_cli import main as dataset_main

    if len(sys.argv) > 1 and sys.argv[1] in COMMANDS:
        sys.exit(dataset_main(sys.argv[1:]))
    from .cli import main

    main()
