"""The ``cases`` experiment (``experiment.kind: cases``, the default): every method on
every case of the configured dataset (FAUST, DeFAUST, shapes), metrics and tables.

- :mod:`~eval.experiments.cases.cases_experiment`: the run (setup, resume, per-case outputs,
  tables), registered as ``cases``
  (found by the registry's discovery: this package imports nothing, so that the code
  of a run's rows does not import the presentation the experiment module does);
- :mod:`~eval.experiments.cases.case_plan`: the plan logged before any run (and a DeFAUST
  build planned before it is made);
- :mod:`~eval.experiments.cases.pair`: one (case, method) run, guarded, measured and stored;
- :mod:`~eval.experiments.cases.case_references`: the reference columns (distance to a
  deep-converged minimiser);
- :mod:`~eval.experiments.cases.case_jobs`: whole cases side by side in worker processes (``jobs``).
"""
