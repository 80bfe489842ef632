"""DeFAUST, the deformation dataset of the SShaDe paper's appendix A: its builder and its
reader. Build with ``python -m defaust out=DIR`` (:mod:`defaust.build`; sources ``anny``,
the default, ``faust`` and ``synthetic``), read with :func:`defaust.load` (NumPy arrays, no
Hydra), check with :func:`defaust.verify` or ``python -m defaust verify DIR``, write for
other tools with ``python -m defaust export`` (:mod:`defaust.export`), hand on with
``python -m defaust pack`` (:mod:`defaust.packing`), feed PyTorch with
:func:`defaust.torch_dataset` and :func:`defaust.collate_cases`. Mesh file I/O is
:mod:`sshade.mesh.io`. The file format, the datasheet, how to load a build and a map of
the modules: docs/defaust.md.
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
