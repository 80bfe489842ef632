"""The run folder: what one evaluator run claims, plans, stores and records.

The evaluator's ground floor (tests/test_layering.py): it imports no other part of
:mod:`eval`, every other part may import it. The folder claim and its no-harm rules
(``outdir``), the result store and the code identity its rows are keyed by (``result_store``,
``code_identity``), file names for case and method names (``names``) and values as plain
JSON (``jsonsafe``), the up-front plan and the cost-weighted progress (``plan``,
``progress``), ``run.json`` (``runinfo``), the case subsets (``subset``), paths against the
launch directory (``paths``) and the memory probe (``memory``).
"""
