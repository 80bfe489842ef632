"""A method whose results were computed elsewhere: :class:`ScoredResults` reads the
deformed mesh of each case from a results folder (:mod:`eval.exchange.layout`) and the
evaluator scores it like any row (``python -m eval experiment=score``).

It is a case-aware method: the evaluator sets its ``case`` attribute
(:class:`eval.datasets.deformation_case.CaseLabel`) before each ``deform`` call, so it knows which
file to read. Its ``info`` carries ``reported_time_s`` (the method's own seconds from the
times file, or None), which the evaluator puts in the Time column, marked as reported,
instead of the time it took to read the file.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np

from defaust.store import sha256_file
from eval.config_schema import register_section
from eval.exchange.layout import RESULT_EXTS, read_times, result_path
from eval.run.paths import abs_path
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

__all__ = ["ScoreConfig", "ScoredResults", "same_faces"]


@dataclass
class ScoreConfig:
    """The ``score`` section (conf/experiment/score.yaml), typed: ``results``, ``name`` and
    ``times``, the arguments of :class:`ScoredResults`, which its method entry passes on
    (``${score.results}``, ...) and which checks them."""

    results: Optional[str] = None
    name: Optional[str] = None
    times: Optional[str] = None


register_section("score", ScoreConfig)


def same_faces(F: np.ndarray, G: np.ndarray) -> bool:
    """Whether triangle lists ``F`` (m, 3) and ``G`` (k, 3) hold the same oriented
    triangles, in any order of the faces and any rotation of a face's corners."""
    if F.shape != G.shape:
        return False

    def canon(A):
        r = np.argmin(A, axis=1)
        A = np.stack([A[np.arange(len(A)), (r + i) % 3] for i in range(3)], axis=1)
        return A[np.lexsort(A.T[::-1])]
    return bool(np.array_equal(canon(np.asarray(F, np.int64)), canon(np.asarray(G, np.int64))))


class ScoredResults:
    """Results computed outside the harness, one mesh per case, as a method's row.

    Parameters
    ----------
    results : str or Path, the folder of ``<case>.obj`` (or .ply, .off) files,
        relative to the directory the command was started from.
    name : str, the row's name (:data:`sshade.method_interface.NAME_RULE`).
    times : str, Path or None, a CSV of the method's own times (``case,time_s,machine``,
        :func:`eval.exchange.layout.read_times`); None: the Time column stays empty.

    Raises
    ------
    SShaDeError when ``results`` is not a folder or the times file is unreadable or
    malformed (naming the file and line), before any case runs.
    """

    def __init__(self, results, name: str, times=None):
        if results in (None, ""):
            raise SShaDeError("score.results is not set: pass score.results=DIR, the folder of <case>.obj files")
        if name in (None, ""):
            raise SShaDeError("score.name is not set: pass score.name=NAME, the row's name")
        self.results = abs_path(results)
        if not self.results.is_dir():
            raise SShaDeError(f"score.results: {self.results} is not a folder")
        self.name = name
        self.times_path = None if times in (None, "") else abs_path(times)
        self.times = {} if self.times_path is None else read_times(self.times_path)
        self.case = None   # set by the evaluator before each deform (eval.datasets.deformation_case.CaseLabel)
        self.info: dict = {}
        self.key_extra = {"results": self._listing_digest(),
                          "times": None if self.times_path is None else sha256_file(self.times_path)}

    def _listing_digest(self) -> str:
        """SHA-256 of the name, size and modification time of every result file: a
        stored row is scored again when one of its files changes."""
        h = hashlib.sha256()
        for n in sorted(os.listdir(self.results)):
            if Path(n).suffix.lower() in RESULT_EXTS:
                st = os.stat(self.results / n)
                h.update(json.dumps([n, st.st_size, st.st_mtime_ns]).encode())
        return h.hexdigest()

    def deform(self, V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """The result mesh of the current case (``self.case``), checked against its rest mesh.

        Parameters
        ----------
        V : (n, 3) float64 rest vertices; F : (m, 3) int64 faces; handles (h,), targets
            (h, 3): the case's (the handle error is measured by the evaluator).

        Returns
        -------
        (n, 3) float64, the deformed vertices read from the file.

        Raises
        ------
        SShaDeError (a failed case, with its reason): no case set, no result file or two,
        an unreadable file or one that is not a triangle mesh, a vertex count other than
        ``n``, non-finite coordinates, faces other than the rest mesh's.
        """
        if self.case is None:
            raise SShaDeError(f"{self.name}: no case given; scored results run through python -m eval "
                              "experiment=score, which tells the method each case")
        self.info = {}
        name = self.case.name
        path = result_path(self.results, name)
        U, G = read_mesh(path, validate=False)
        if len(U) != len(V):
            raise SShaDeError(f"{path.name}: {len(U)} vertices, the rest mesh of {name} has {len(V)} (the result "
                              "must keep the rest mesh's vertices, in their order)")
        bad = ~np.isfinite(U).all(axis=1)
        if bad.any():
            raise SShaDeError(f"{path.name}: {int(bad.sum())} vertices are not finite (the first: vertex "
                              f"{int(np.flatnonzero(bad)[0])})")
        if not same_faces(np.asarray(F), G):
            if len(G) == len(F):
                raise SShaDeError(f"{path.name}: its {len(G)} faces join other vertices than the rest mesh's (same "
                                  "count): the vertices were reordered (Open3D's OBJ reader does; keep the rest "
                                  "mesh's order, e.g. read rest.ply) or the mesh was remeshed")
            raise SShaDeError(f"{path.name}: {len(G)} faces, the rest mesh of {name} has {len(F)} (the result must "
                              "keep the rest mesh's faces: it was remeshed?)")
        t = self.times.get(name)
        self.info = {"result_file": path.name, "result_sha256": sha256_file(path),
                     "reported_time_s": None if t is None else t.time_s,
                     "time_machine": None if t is None else t.machine}
        if t is not None and t.iterations is not None:  # how it stopped, as the method reported it
            self.info["iterations"] = t.iterations
        if t is not None and t.converged is not None:
            self.info["converged"] = t.converged
            self.info["status"] = "converged" if t.converged else "reported as stopped before its criterion"
        return U
