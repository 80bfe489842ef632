"""``python -m eval.sweeps [-m] [KEY=VALUE ...] | resume DIR | aggregate DIR...``: the sweep
command, :func:`eval.sweeps.sweep_command.main` (its help: ``--help``)."""
# The command lives in eval.sweeps.sweep_command, imported under its real name, so that
# launchers pickle its sweep_job by reference (a __main__ function would not resolve in
# their worker processes).
from sshade.numba_cache import ensure_cache

ensure_cache()  # before the first kernel module: a command runs where numba cannot cache

from eval.sweeps.sweep_command import main  # noqa: E402

if __name__ == "__main__":
    main()
