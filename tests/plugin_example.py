"""The plug-in method of the README's "Add your method" section (the code below the
marker line is that section's Python block, character for character; tests/test_plugins.py
checks it), importable from the repository root as ``tests.plugin_example.MyMethod``:

    python -m eval dataset=faust dataset.root=../shared/data/faust_reg dataset.limit=2 \\
        'methods=[SShaDe,{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:20}]'
"""
# --- README example ---
import numpy as np
import scipy.sparse as sp


class MyMethod:
    """Spread the handles' displacements over the mesh: `iterations` Jacobi steps of the
    uniform graph Laplacian (a toy method, far from ARAP; shows the interface only)."""

    def __init__(self, name="Mine", iterations=20):
        self.name = name                    # the row label in table.md / cases.csv
        self.iterations = int(iterations)
        self.info = {}                      # numeric entries go to cases.csv

    def deform(self, V, F, handles, targets):
        """V (n, 3) float64, F (m, 3) int64, handles (h,) int64, targets (h, 3) -> (n, 3)."""
        n = len(V)
        i = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
        j = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
        A = sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
        A.data[:] = 1.0                     # each edge once
        W = sp.diags(1.0 / np.asarray(A.sum(axis=1)).ravel()) @ A
        D = np.zeros((n, 3))
        D[handles] = targets - V[handles]
        for _ in range(self.iterations):
            D = W @ D                       # average of the neighbours' displacements
            D[handles] = targets - V[handles]
        self.info = {"iterations": self.iterations, "moved": int((np.abs(D).sum(1) > 0).sum())}
        return V + D
