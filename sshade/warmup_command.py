"""``python -m sshade warmup``: compile every numba kernel of the built-in methods ahead, so
that no later call waits for it.

Fills numba's cache (:mod:`sshade.kernel_cache`) with SShaDe's kernels (on two processes
where it is cold), then warms SShaDe's whole pipeline, the full-resolution ARAP solver of
the ARAP and Elastic baselines (serial and parallel kernels, both protocols) and what other
installed packages register under the entry-point group ``sshade.warmup`` (the baselines'
ARAP-SR). One line per stage on stdout, then where the cache is and how to share it.
Later processes load the kernels from the cache; an upgrade of sshade or numba, or
another machine, compiles them again.
"""
from __future__ import annotations

import sys
import time
from importlib.metadata import entry_points

from .command_errors import ArgumentParser, run_command
from .kernel_cache import cache_folder, compile_kernels
from .params import check_params
from .pipeline import warm_sshade
from .warmup import warm_fullres, warm_parallel_kernels

__all__ = ["ENTRY_POINTS", "warm_everything", "main"]

#: Entry-point group of other packages' warm-ups: each a callable taking no argument.
ENTRY_POINTS = "sshade.warmup"


def _stages():
    """(label, callable) for every stage, SShaDe's first."""
    yield "SShaDe kernels", lambda: compile_kernels(show_notice=False, progress=lambda s: print(f"  {s}", flush=True))
    yield "SShaDe pipeline", lambda: warm_sshade(check_params())
    for energy, method in (("spokes", "ARAP"), ("spokes_and_rims", "Elastic")):
        for protocol in ("converged", "paper"):
            yield f"{method} ({protocol} protocol)", lambda e=energy, p=protocol: warm_fullres(e, p)
    yield "full-resolution ARAP and ARAP-SR, parallel kernels", lambda: warm_parallel_kernels(smooth_rotations=True)
    for ep in sorted(entry_points(group=ENTRY_POINTS), key=lambda e: e.name):
        yield ep.name, lambda ep=ep: ep.load()()


def warm_everything(out=None) -> float:
    """Run every stage of the module docstring, one line each on ``out`` (stdout).

    Returns
    -------
    float, the seconds spent. Errors of a stage propagate (a kernel that cannot compile
    here would fail in the real call too).
    """
    out = out or sys.stdout
    t0 = time.perf_counter()
    print(f"sshade warmup: compiling every kernel once; numba's cache: {cache_folder() or 'none'}", file=out,
          flush=True)
    for label, run in _stages():
        t = time.perf_counter()
        run()
        print(f"{label}: {time.perf_counter() - t:.1f} s", file=out, flush=True)
    total = time.perf_counter() - t0
    print(f"done in {total:.1f} s. Later processes load these kernels from the cache; an upgrade of sshade or "
          "numba, or another machine, compiles them again. On a cluster, set NUMBA_CACHE_DIR to a folder every "
          "node reads and run this once there.", file=out, flush=True)
    return total


def main(argv=None) -> int:
    """``python -m sshade warmup``: exit status 0, 2 after one ``error:`` line, 130 on Ctrl-C."""
    p = ArgumentParser(prog="python -m sshade warmup", description=__doc__.split("\n\n")[0])
    p.parse_args(argv)
    return run_command(warm_everything)
