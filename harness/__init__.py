"""The harness's shared tools, the floor between the method (:mod:`sshade`) and what is
built on it (:mod:`baselines`, :mod:`defaust`, :mod:`eval`): Hydra command lines refused
in one ``error:`` line before any work (:mod:`harness.command`), where the configs are
(:mod:`harness.confdir`), checked values and typed records' declared fields (:mod:`harness.checks`), a method built
from a ``_target_`` mapping (:mod:`harness.plugins`) or by name (:mod:`harness.method_registry`),
jobs in worker processes (:mod:`harness.jobs`), and ``python -m harness deform``, ``python
-m sshade deform`` for every method (:mod:`harness.__main__`). Nothing in :mod:`sshade`
imports this package; Hydra and OmegaConf are imported here, not below (docs/layout.md).
"""
