"""Helpers shared by the experiments of :mod:`eval.experiments`."""
from __future__ import annotations

from eval.run.spec import EvalSpec
from sshade.pipeline import SShaDe

__all__ = ["as_list", "sshade_spec", "SSHADE_TRANSFER_KEYS"]

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


def sshade_spec(spec: EvalSpec) -> dict:
    """SShaDe's parameters from the one place every experiment reads them: the method
    definition ``method.SShaDe`` (``conf/method/SShaDe.yaml``, whose values default to the
    ``sshade`` section and, for the low-res ARAP's stopping rule, to ``arap``), resolved
    (:func:`eval.config_check.method_definition`); ``_target_`` and ``name`` left out.

    Returns
    -------
    dict with ``n_low`` (int or ``"auto"``), ``n_samplings``, ``seed``, ``workers``,
    ``gradient``, ``anchor``, ``warm_start``, ``energy``, ``transfer``, ``average``,
    ``tol``, ``max_iter``, ``protocol``, ``etol``, ``gtol``
    (unchecked; :func:`sshade.pipeline.check_params` checks them).
    """
    return {k: v for k, v in spec.definition(SShaDe.name).items() if k not in ("_target_", "name")}
