"""``python -m eval [overrides]``: run the evaluator (see :mod:`eval.app`)."""
from sshade.numba_cache import ensure_cache

ensure_cache()  # before the first kernel module: a command runs where numba cannot cache

from eval.app import main  # noqa: E402

if __name__ == "__main__":
    main()
