"""The airspeed-velocity (asv) suite of SShaDe: the speed record across commits
(``asv.conf.json`` at the repository root; how to run it: docs/layout.md, "Speed record
(asv)"). Only this folder is discovered by asv; the other scripts of ``benchmarks/`` are
stand-alone programs and are never imported by it.

- :mod:`.sshade_time`: one-shot ``sshade.deform``, a prepared frame, the remesh alone,
  the transfer alone, a DeFAUST case;
- :mod:`.versus_libigl`: SShaDe against libigl's spokes-and-rims local/global on the
  hard mesh (the paper's 1000-iteration protocol, one iteration against one frame);
- :mod:`.fullres`: the full-resolution baselines (converged Elastic, ARAP-SR) on the
  survey-style cases of ``sshade.arap.problems``, and Elastic against libigl at equal energy.

The meshes (a ~200k clean armadillo, the hard LS3-subdivided 252k centaur) are built
once into a cache outside the repository (:mod:`._common`).
"""
