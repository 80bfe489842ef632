"""Datasets of deformation cases for the evaluator (``dataset.name`` in the config).
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py); notes: docs/implementation.md.

- :mod:`eval.datasets.faust`: FAUST registrations -> DeFAUST-style cases
  (:func:`~eval.datasets.faust.faust_cases`).
- :mod:`eval.datasets.defaust_dataset`: a DeFAUST build (``python -m defaust``), read by
  :func:`~eval.datasets.defaust_dataset.load_defaust` at high or low resolution (and built
  first into the default folder, ``dataset.build.enabled``).
- :mod:`eval.datasets.shapes`: single shapes (Stanford models) with a fixed user-defined
  edit (:func:`~eval.datasets.shapes.shape_cases`; paper §4.1, Fig. arap-examples).
- :mod:`eval.datasets.dataset_options`: the keys every dataset's options dataclass shares.
- :mod:`eval.datasets.loading`: the section at work (cases by name, root)."""
import lazy_loader

# bound on first use (SPEC 1): a module that needs one name (the pair runner's case label)
# runs no loader, so a row's code identity holds no loader (docs/implementation.md)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "dataset_options": ["DatasetOptions"],
    "dataset_registry": ["Dataset", "datasets", "find_dataset", "register_dataset"],
    "deformation_case": ["DeformationCase"],
    "faust": ["Case", "FAUST_LANDMARKS", "FaustOptions", "discover_faust", "faust_cases"],
    "loading": ["dataset_named", "dataset_names", "dataset_outlook", "dataset_root", "load_cases",
                "unique_case_names"],
})
