"""Results computed outside this harness: the exchange layout and its scoring.
Floor 2 of eval/ (eval/exchange/, tests/test_layering.py); notes: docs/implementation.md.

- :mod:`~eval.exchange.layout`: ``python -m eval experiment=export`` writes every case of
  a dataset in a layout any language reads (rest mesh as OBJ and PLY, handles and
  targets as JSON, CSV and libigl's DMAT, a ``cases.json`` index), named as the
  evaluator names its cases;
- the user's program writes one deformed mesh per case, ``<case>.obj`` (or .ply/.off);
- :mod:`~eval.exchange.scored`: ``python -m eval experiment=score score.results=DIR
  score.name=NAME`` scores that folder like any method's row (a plug-in that reads the
  case's file), with the times the method reported (``score.times``), never read times."""
