"""``python -m eval [overrides]``: run the evaluator (see :mod:`eval.app`)."""
from eval.app import main

if __name__ == "__main__":
    main()
