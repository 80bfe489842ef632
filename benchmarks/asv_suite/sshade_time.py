"""SShaDe's own times on the two 200k meshes: one-shot deform, a prepared frame, the
remesh alone, the transfer alone; a DeFAUST case where a build exists; and the cold first
call of a fresh process on the bunny.

``mesh`` (the parameter): ``clean`` = the Stanford armadillo LS3-subdivided and
isotropically remeshed to about 200k vertices; ``hard`` = the TOSCA centaur0 LS3
Loop-subdivided to 252k vertices (its thin parts and anisotropy kept), as the scaling
experiment builds them (:mod:`._common`). SShaDe runs with n_low=6000, n_samplings=5,
seed=0 (paper §4.1) and its default workers.
"""
import inspect
import os
import statistics
import subprocess
import sys
import tempfile

import numpy as np

from ._common import (
    SSHADE,
    arap_deform,
    defaust_root,
    load_mesh,
    mesh_files,
    prepared_frames,
    shared_data,
    skip,
    warm_deform,
)

MESH_PARAMS = ["clean", "hard"]


class Deform:
    """One-shot ``sshade.deform`` (n_low=6000, n_samplings=5, seed=0) on the clean
    armadillo (~200k) or the hard centaur (252k): remesh, low-res ARAP and transfer of
    the five samplings and their average. Compilation is kept out by one untimed call
    per process. Reference on a quiet 2-core machine: 1.03 s clean, 1.49 s hard
    (results/frames' one-shot column, d9750d7)."""

    params = MESH_PARAMS
    param_names = ["mesh"]
    number = 1
    repeat = (2, 5, 20.0)
    rounds = 2
    warmup_time = 0
    timeout = 300

    def setup_cache(self):
        return mesh_files()

    setup_cache.timeout = 1800  # the first build of the meshes (cached outside the repository)

    def setup(self, files, mesh):
        self.V, self.F, self.h, self.T = load_mesh(files, mesh)
        warm_deform(self.V, self.F, self.h, self.T, files[mesh])

    def time_deform(self, files, mesh):
        """sshade.deform on the clean or the hard 200k mesh (see the class)."""
        import sshade
        sshade.deform(self.V, self.F, self.h, self.T, **SSHADE)


class PreparedFrame:
    """A frame of a prepared SShaDe: ``p = sshade.prepare(V, F, handles)`` (n_low=6000,
    n_samplings=5, seed=0), one untimed first solve, then the median seconds of
    ``p.solve(targets_t)`` over frames 2-60 of benchmarks/frames.py's smooth
    (smoothstep) 60-frame path from the rest positions to the scaling edit's targets, so
    that each frame moves the handles as much as in results/frames (``prepared_frames``
    in ``_common``). Target: <= 0.100 s at 200k on both meshes (results/frames at e0b4e30:
    57 ms clean, 80 ms hard, 2-core machine). n/a where ``sshade.prepare`` does not exist."""

    params = MESH_PARAMS
    param_names = ["mesh"]
    timeout = 300

    def setup_cache(self):
        return mesh_files()

    setup_cache.timeout = 1800

    def setup(self, files, mesh):
        import sshade
        if not hasattr(sshade, "prepare"):
            raise skip("sshade.prepare does not exist at this commit")
        self.V, self.F, self.h, self.T = load_mesh(files, mesh)

    def track_frame_median(self, files, mesh):
        """Median seconds of a prepared frame (frames 2-60, after the first solve)."""
        return statistics.median(prepared_frames(self.V, self.F, self.h, self.T))

    track_frame_median.unit = "seconds"


_STAGE_STATE: dict = {}


def _stage_state(files, mesh, V, F, h, T):
    """One sampling's remesh, projection and low-res spokes-and-rims ARAP (seed 0), once
    per process and mesh: the input of the timed transfer."""
    key = files[mesh]
    if key not in _STAGE_STATE:
        from sshade.projection import project_to_fans
        from sshade.remesh import remesh
        rm = remesh(V, F, SSHADE["n_low"], seed=SSHADE["seed"], required=h)
        proj = project_to_fans(V, rm.label, V[rm.seeds], rm.F)
        VN = V[rm.seeds]
        res = arap_deform(VN, rm.F, rm.label[h], T, "spokes_and_rims")
        _STAGE_STATE[key] = {"tri": proj.tri, "bary": proj.bary, "VN": VN, "VNd": res.V, "FN": rm.F}
    return _STAGE_STATE[key]


class Stages:
    """SShaDe's stages alone on one sampling (seed 0) of the clean or the hard 200k mesh:

    - ``time_remesh``: ``sshade.remesh.remesh(V, F, 6000, seed=0, required=handles)``, the
      topology-preserving remesh (paper §3.1; its mesh topology included);
    - ``time_transfer``: ``sshade.lrf.transfer`` of the low-res ARAP's result onto the
      whole mesh (Alg. 1: frame functions, encoding, decoding), anchored at the
      projection where the function takes ``bary`` (as ``sshade.deform`` calls it at that
      commit), at the barycenter before.
    """

    params = MESH_PARAMS
    param_names = ["mesh"]
    number = 1
    repeat = (3, 10, 15.0)
    rounds = 2
    warmup_time = 0
    timeout = 300

    def setup_cache(self):
        return mesh_files()

    setup_cache.timeout = 1800

    def setup(self, files, mesh):
        try:
            from sshade.lrf import transfer  # noqa: F401
            from sshade.remesh import remesh  # noqa: F401
        except ImportError as e:
            raise skip(f"no public remesh / transfer at this commit: {e}") from None
        self.V, self.F, self.h, self.T = load_mesh(files, mesh)
        self.state = _stage_state(files, mesh, self.V, self.F, self.h, self.T)  # also warms the kernels

    def time_remesh(self, files, mesh):
        """sshade.remesh.remesh to n_low=6000 with the handles required."""
        from sshade.remesh import remesh
        remesh(self.V, self.F, SSHADE["n_low"], seed=SSHADE["seed"], required=self.h)

    def time_transfer(self, files, mesh):
        """sshade.lrf.transfer of one sampling's low-res result to the whole mesh."""
        from sshade.lrf import transfer
        s = self.state
        kw = {"bary": s["bary"]} if "bary" in inspect.signature(transfer).parameters else {}
        transfer(self.V, s["tri"], s["VN"], s["VNd"], s["FN"], gradient="normalized", **kw)


_DEFAUST: dict = {}


class DefaustCase:
    """One-shot ``sshade.deform`` (n_low=6000, n_samplings=5, seed=0) on the first case of
    a DeFAUST build (high resolution, 150k-200k vertices; ``data/defaust`` or
    ``SSHADE_DEFAUST``), read with ``defaust.load``. Reference: SShaDe 1.29 s per case on
    2 cores (results/defaust). n/a without a build or where ``defaust.load`` does not exist."""

    number = 1
    repeat = (2, 5, 20.0)
    rounds = 2
    warmup_time = 0
    timeout = 300

    def setup(self):
        root = defaust_root()
        if not root.is_dir():
            raise skip(f"no DeFAUST build at {root} (set SSHADE_DEFAUST)")
        import defaust
        if not hasattr(defaust, "load"):
            raise skip("defaust.load does not exist at this commit")
        if "case" not in _DEFAUST:
            try:  # the README's main job's build holds some subjects only: partial=True takes them
                c = defaust.load(root, limit=1, partial=True)[0]
            except TypeError:  # a commit whose load has no partial
                c = defaust.load(root, limit=1)[0]
            _DEFAUST["case"] = (np.asarray(c.V, np.float64), np.asarray(c.F, np.int64), c.handles, c.targets)
        self.V, self.F, self.h, self.T = _DEFAUST["case"]
        warm_deform(self.V, self.F, self.h, self.T, ("defaust", str(root)))

    def time_defaust_deform(self):
        """sshade.deform on the first DeFAUST case."""
        import sshade
        sshade.deform(self.V, self.F, self.h, self.T, **SSHADE)


# the README's API example in a fresh process: 50 lowest vertices fixed, 50 highest moved 15 % of the
# diagonal along x; prints the seconds of the first sshade.deform (after the imports)
_COLD_PROBE = r"""
import sys, time
import numpy as np
from sshade import deform
from sshade.mesh.io import read_mesh
V, F = read_mesh(sys.argv[1])
order = np.argsort(V[:, 1])
h = np.r_[order[:50], order[-50:]]
T = V[h].copy()
T[50:] += [0.15 * np.linalg.norm(V.max(0) - V.min(0)), 0, 0]
t = time.perf_counter()
deform(V, F, h, T, n_low=1000, n_samplings=5, seed=0)
print(time.perf_counter() - t)
"""


class ColdFirstCall:
    """The first ``sshade.deform`` of a fresh process on an empty numba cache (a fresh
    install, an upgrade, a new node): the README's API example on the bunny (3,485 vertices,
    n_low 1000, n_samplings 5, seed 0), as ``benchmarks/cold_start.py``'s probe; every kernel
    the call takes is compiled in it (on two processes where two cores are free). The median
    of three fresh processes. Target: <= 8 s on 2 cores (the solver issue; results/cold_start)."""

    number = 1
    repeat = 1
    rounds = 2
    warmup_time = 0
    timeout = 600

    def setup(self):
        self.bunny = shared_data() / "classic" / "bunny.off"
        if not self.bunny.is_file():
            raise skip(f"no {self.bunny} (set SSHADE_SHARED_DATA)")

    def track_cold_first_call(self):
        """Seconds of the first sshade.deform in a fresh process on an empty numba cache."""
        runs = []
        for _ in range(3):
            with tempfile.TemporaryDirectory() as cache:
                env = dict(os.environ, NUMBA_CACHE_DIR=cache)
                r = subprocess.run([sys.executable, "-c", _COLD_PROBE, str(self.bunny)], env=env, cwd=cache,
                                   capture_output=True, text=True, timeout=300)
                if r.returncode != 0:
                    raise RuntimeError(r.stderr.strip().splitlines()[-1:])
                runs.append(float(r.stdout.strip().splitlines()[-1]))
        return statistics.median(runs)

    track_cold_first_call.unit = "seconds"
