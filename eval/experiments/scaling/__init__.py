"""The ``scaling`` experiment (``experiment.kind: scaling``): SShaDe against full-resolution
Elastic on a set of meshes (one clean, two hard) at about 200k and 1M vertices.

- :mod:`~eval.experiments.scaling.scaling_experiment`: the run and the meshes' cached builds,
  registered as ``scaling``
  (found by the registry's discovery: this package imports nothing, so that the code
  of a run's rows does not import the presentation the experiment module does);
- :mod:`~eval.experiments.scaling.mesh_set`: the set of meshes and their sizes;
- :mod:`~eval.experiments.scaling.probe`: the first call of a fresh process
  (``python -m eval.experiments.scaling.probe``);
- :mod:`~eval.experiments.scaling.scaling_table`: its tables.
"""
