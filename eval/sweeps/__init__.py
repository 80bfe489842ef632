"""Sweeps: the command (``sweep_command``, run as ``python -m eval.sweeps``), the files of a
sweep folder (``files``), its aggregated table (``sweep_table``) and the SLURM launcher
behind ``hydra/launcher=slurm`` (``launcher``).
"""
