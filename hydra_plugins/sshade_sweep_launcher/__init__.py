"""Hydra launcher plugin of this project: ``SweepSlurmLauncher``, hydra-submitit-launcher's
SLURM launcher with a ``launch`` that tolerates dead jobs and resumes sweeps
(:mod:`eval.sweeps.launcher`). Hydra instantiates launchers only from the ``hydra_plugins``
namespace package, hence this module; the logic lives in :mod:`eval.sweeps.launcher`.

Config ``hydra/launcher=sweep_slurm`` (registered below: the plugin's ``submitit_slurm``
settings plus ``poll_s``, ``grace_polls``, ``unreachable_s``); the project's
``conf/hydra/launcher/slurm.yaml`` builds on it.
"""
# no `from __future__ import annotations`: Hydra's plugin scanner runs this module before
# it is in sys.modules, where dataclasses would look string annotations up
from dataclasses import dataclass

from hydra.core.config_store import ConfigStore
from hydra_plugins.hydra_submitit_launcher.config import SlurmQueueConf
from hydra_plugins.hydra_submitit_launcher.submitit_launcher import SlurmLauncher

from eval.sweeps.launcher import TolerantLauncherMixin

__all__ = ["SweepSlurmLauncher", "SweepSlurmConf"]


class SweepSlurmLauncher(TolerantLauncherMixin, SlurmLauncher):
    """SLURM launcher whose sweeps end with every job's outcome (done, partial, failed,
    killed), with or without SLURM accounting (:class:`eval.sweeps.launcher.TolerantLauncherMixin`)."""


@dataclass
class SweepSlurmConf(SlurmQueueConf):
    """``submitit_slurm``'s settings plus how the launcher waits on its jobs."""

    _target_: str = "hydra_plugins.sshade_sweep_launcher.SweepSlurmLauncher"
    poll_s: float = 10.0        # seconds between two looks at the jobs
    grace_polls: int = 2        # polls a job must be gone (no result) before it counts as killed
    unreachable_s: float = 1800.0  # SLURM unanswering that long: the jobs without result are killed


ConfigStore.instance().store(group="hydra/launcher", name="sweep_slurm", node=SweepSlurmConf,
                             provider="sshade_sweep_launcher")
