"""The harness's shared tools, the floor between the method (:mod:`sshade`) and what is
built on it (:mod:`baselines`, :mod:`defaust`, :mod:`eval`).

- :mod:`harness.command`: Hydra command lines refused in one ``error:`` line before any
  work (:func:`~harness.command.hydra_main`, :func:`~harness.command.run_command`).
- :mod:`harness.confdir`: where the configs are (the repository's ``conf/`` or the
  installed copy).
- :mod:`harness.checks`: checked numbers, flags and lists read from a config.
- :mod:`harness.plugins`: a method built from a ``_target_`` mapping.
- :mod:`harness.registry`: the built-in methods by name, one ``conf/method/<name>.yaml``
  each, and what the harness knows of them (``harness:``).
- :mod:`harness.jobs`: jobs in worker processes (a DeFAUST build's subjects, an
  evaluation's cases).
- ``python -m harness deform``: ``python -m sshade deform`` for every built-in method
  and plug-in (:mod:`harness.__main__`).

Nothing in :mod:`sshade` imports this package; Hydra and OmegaConf are imported here,
not below.
"""
