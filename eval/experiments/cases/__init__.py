"""The ``cases`` experiment (``experiment.kind: cases``, the default): every method on
every case of the configured dataset (FAUST, DeFAUST, shapes), metrics and tables.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

- :mod:`~eval.experiments.cases.cases_experiment`: the run, registered as ``cases``;
- :mod:`~eval.experiments.cases.case_plan`: the plan logged before any run;
- :mod:`~eval.experiments.cases.pair`: one (case, method) run, guarded, measured and stored;
- :mod:`~eval.experiments.cases.case_references`: the reference columns;
- :mod:`~eval.experiments.cases.case_jobs`: whole cases side by side in worker processes (``jobs``)."""
