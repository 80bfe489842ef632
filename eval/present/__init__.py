"""Presentation: what a run's tables, figures and browser report are drawn with.

Table text (``table_markup``), figures (``figures``, ``anny_figures``), per-group
breakdowns (``breakdown``), the report's 3D views (``meshview``) and its scope
(``report_scope``), and the stdlib PNG helpers (``render``). The commands that write them
are :mod:`eval.tables` and :mod:`eval.report`.
"""
