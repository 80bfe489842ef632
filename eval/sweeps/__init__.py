"""Sweeps: the files of a sweep folder (``files``), its aggregated table (``table``) and
the SLURM launcher behind ``hydra/launcher=slurm`` (``launcher``). The command is
:mod:`eval.sweep`.
"""
