"""Metrics: what a result is scored by. The deformation and ground-truth metrics of
Table 1 (``measures``, paper §4), the rest and ground-truth meshes they share per case
(``meshes``), and the distance to a deep-converged minimiser (``reference``).
"""
