"""DeFAUST cases for PyTorch's ``DataLoader`` (the ``[neural]`` extra: ``pip install -e
.[neural]``): a map-style dataset of dicts of tensors (:func:`torch_dataset`) and a collate
function for meshes of different vertex counts (:func:`collate_cases`: each per-case array
a list of ``B`` tensors, no padding; the scalars stacked into ``(B,)`` tensors). The module
imports without PyTorch: :func:`torch_dataset` then raises an SShaDeError saying what to
install, while :func:`case_item` and :func:`collate_cases` work on NumPy arrays. Usage:
docs/defaust.md §6, "With PyTorch".
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sshade.errors import SShaDeError

try:  # the [neural] extra; any failure to load it counts as absent
    import torch
    from torch.utils.data import Dataset as _TorchDataset
    _TORCH_ERROR = None
except Exception as e:  # ImportError, OSError (a library that does not load), RuntimeError, ...
    torch, _TorchDataset = None, object
    _TORCH_ERROR = f"{type(e).__name__}: {(str(e).strip().splitlines() or [''])[0]}"

__all__ = ["ITEM_ARRAYS", "ITEM_SCALARS", "ITEM_STRINGS", "case_item", "collate_cases", "torch_dataset",
           "CaseDataset"]

#: Per-case arrays of an item (sizes vary between cases): V (n, 3) float64 metres, F (m, 3)
#: int64, handles (h,) int64, targets (h, 3) float64, static (h,) bool, group (h,) int64,
#: snap_distance (h,) float64 metres, and V_gt (n, 3) float64 where the case has one.
ITEM_ARRAYS = ("V", "F", "handles", "targets", "static", "group", "snap_distance", "V_gt")
#: Scalars of an item, () int64 arrays: subject, pose, n_dropped, seed (-1 for none).
ITEM_SCALARS = ("subject", "pose", "n_dropped", "seed")
#: Text of an item: name, pose_name, resolution, source (str), landmark_names (tuple of str).
ITEM_STRINGS = ("name", "pose_name", "resolution", "source", "landmark_names")
_FLOATS = ("V", "targets", "snap_distance", "V_gt")


def case_item(case) -> dict:
    """A case as one item of :func:`torch_dataset`, with NumPy arrays (no PyTorch).

    Parameters
    ----------
    case : :class:`defaust.dataset.Case`.

    Returns
    -------
    dict: :data:`ITEM_ARRAYS` (the case's own arrays, not copies; ``V_gt`` only where the
    case has a ground truth), :data:`ITEM_SCALARS` as () int64 arrays and
    :data:`ITEM_STRINGS`.

    Example::

        item = case_item(defaust.load("data/defaust")[0])
        item["V"].shape, item["subject"], item["name"]
        # -> ((168855, 3), array(0), 's00_p01')
    """
    d = {k: getattr(case, k) for k in ITEM_ARRAYS if getattr(case, k) is not None}
    d.update(subject=np.int64(case.subject), pose=np.int64(case.pose), n_dropped=np.int64(case.n_dropped),
             seed=np.int64(-1 if case.seed is None else case.seed))
    d = {k: (np.asarray(v) if k in ITEM_SCALARS else v) for k, v in d.items()}
    d.update(name=case.name, pose_name=case.pose_name, resolution=case.resolution, source=case.source,
             landmark_names=tuple(case.landmark_names))
    return d


def collate_cases(items: Sequence[dict]) -> dict:
    """Batch items of :func:`torch_dataset` (tensors) or :func:`case_item` (NumPy arrays)
    for ``DataLoader(..., collate_fn=collate_cases)``.

    Parameters
    ----------
    items : non-empty sequence of dicts with the same keys.

    Returns
    -------
    dict, per key: 0-d values (:data:`ITEM_SCALARS`) stacked into a (B,) tensor (or
    array); everything else, per-case arrays of any size and strings, a list of the B
    values in order (no padding).

    Raises
    ------
    SShaDeError if ``items`` is empty or the items' keys differ (e.g. ground truth in
    some cases and not in others: a FAUST build at high resolution has none).

    Examples
    --------
    >>> items = [{"V": np.zeros((3, 3)), "pose": np.asarray(1)}, {"V": np.zeros((5, 3)), "pose": np.asarray(2)}]
    >>> b = collate_cases(items)
    >>> [v.shape for v in b["V"]], b["pose"].tolist()
    ([(3, 3), (5, 3)], [1, 2])
    """
    if not items:
        raise SShaDeError("collate_cases: no item to batch")
    keys = list(items[0])
    for i, it in enumerate(items):
        if set(it) != set(keys):
            diff = sorted(set(it) ^ set(keys))
            raise SShaDeError(f"collate_cases: item {i} has other keys than item 0 ({', '.join(diff)}); batch cases "
                              "of one build and resolution")
    out = {}
    for k in keys:
        vals = [it[k] for it in items]
        if all(getattr(v, "ndim", None) == 0 for v in vals):
            out[k] = np.stack(vals) if isinstance(vals[0], np.ndarray) else _torch().stack(vals)
        else:
            out[k] = vals
    return out


def _torch():
    """The torch module, or SShaDeError saying how to get it."""
    if torch is None:
        raise SShaDeError(f"PyTorch cannot be imported ({_TORCH_ERROR}); it is the [neural] extra: "
                          "pip install -e .[neural]")
    return torch


class CaseDataset(_TorchDataset):
    """A map-style PyTorch dataset of DeFAUST cases (:func:`torch_dataset` makes it).

    ``dataset[i]`` is :func:`case_item` of ``cases[i]`` with every array a new tensor
    (float arrays in ``float_dtype`` when given); ``len(dataset) == len(cases)``. The
    cases are read when first asked for (:class:`defaust.case_sequence.CaseSequence`); a
    worker process gets a copy that reads its own.
    """

    def __init__(self, cases: Sequence, float_dtype=None):
        self.cases, self.float_dtype = cases, float_dtype

    def __len__(self) -> int:
        return len(self.cases)

    def __getitem__(self, i) -> dict:
        t = _torch()
        out = {}
        for k, v in case_item(self.cases[i]).items():
            if isinstance(v, np.ndarray):
                v = t.tensor(v)
                if self.float_dtype is not None and k in _FLOATS:
                    v = v.to(self.float_dtype)
            out[k] = v
        return out


def torch_dataset(cases: Sequence, *, float_dtype=None) -> CaseDataset:
    """The cases as a map-style dataset that ``torch.utils.data.DataLoader`` takes.

    Parameters
    ----------
    cases : :func:`defaust.load`'s sequence (or any sequence of
        :class:`defaust.dataset.Case`).
    float_dtype : torch dtype or None, of the float tensors (V, targets, snap_distance,
        V_gt); None keeps float64.

    Returns
    -------
    :class:`CaseDataset`; batch it with ``collate_fn=`` :func:`collate_cases`.

    Raises
    ------
    SShaDeError if PyTorch cannot be imported (the message says how to install it), or
    ``float_dtype`` is not a floating torch dtype.

    Example::

        ds = torch_dataset(defaust.load("data/defaust", resolution="low"))
        ds[0]["V"].dtype, ds[0]["F"].shape
        # -> (torch.float64, torch.Size([26692, 3]))
    """
    t = _torch()
    if float_dtype is not None and not (isinstance(float_dtype, t.dtype) and float_dtype.is_floating_point):
        raise SShaDeError(f"float_dtype must be None or a floating torch dtype (torch.float32, ...), "
                          f"got {float_dtype!r}")
    return CaseDataset(cases, float_dtype)
