"""``python -m defaust [overrides]``: build a DeFAUST dataset (see :mod:`defaust.cli`)."""
from .cli import main

if __name__ == "__main__":
    main()
