"""The run folder: what one evaluator run claims, checks, plans, stores and records.

The folder claim and its no-harm rules (``outdir``), the config check (``config_check``),
the result store and the code identity its rows are keyed by (``store``,
``code_identity``), the up-front plan and the cost-weighted progress (``plan``,
``progress``), ``run.json`` (``runinfo``), the case subsets (``subset``), paths against the
launch directory (``paths``) and the memory probe (``memory``).
"""
