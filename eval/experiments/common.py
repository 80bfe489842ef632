"""Helpers shared by the experiments of :mod:`eval.experiments`. SShaDe's parameters, the
same for every experiment, are the run's :attr:`eval.run.spec.EvalSpec.sshade`."""
from __future__ import annotations

from collections.abc import Mapping

__all__ = ["as_list", "transfer_params", "SSHADE_TRANSFER_KEYS"]

#: SShaDe's parameters that its correspondence transfers take
#: (:func:`sshade.isometric.isometric_transfer`, :func:`sshade.isometric.pose_transfer`):
#: no ARAP runs there, so no stopping rule.
SSHADE_TRANSFER_KEYS = ("n_low", "n_samplings", "seed", "gradient", "anchor", "workers", "transfer", "average")


def as_list(x):
    """A config list (ListConfig, list, tuple) or a scalar as a plain list; None stays None."""
    from omegaconf import OmegaConf
    if x is None:
        return None
    if OmegaConf.is_config(x):
        x = OmegaConf.to_container(x)
    return list(x) if isinstance(x, (list, tuple)) else [x]


def transfer_params(params: Mapping) -> dict:
    """The parameters of SShaDe's correspondence transfers (:data:`SSHADE_TRANSFER_KEYS`) of
    its checked parameters ``params`` (:attr:`eval.run.spec.EvalSpec.sshade`)."""
    return {k: params[k] for k in SSHADE_TRANSFER_KEYS if k in params}
