"""defaust.torch_data: a case as a dict of NumPy arrays holds the case's own arrays;
collate_cases keeps meshes of different sizes as lists and stacks the scalars; the module
imports without PyTorch and torch_dataset then says what to install. With PyTorch (the
[neural] extra; mark ``neural``, each test skips with one line when ``import torch``
fails for any reason): DataLoader batches equal the cases, also from an archive read by
worker processes."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import defaust.torch_data as torch_data
from defaust.dataset import load
from defaust.packing import pack
from defaust.torch_data import ITEM_ARRAYS, ITEM_SCALARS, ITEM_STRINGS, case_item, collate_cases, torch_dataset
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env
from .optional import error_line, skip_reason


def _torch():
    """torch, or skip with one line when it cannot be imported for any reason."""
    try:
        import torch
    except Exception as e:  # ImportError, OSError (a library that does not load), RuntimeError, ...
        pytest.skip(skip_reason("torch", error_line(e)))
    return torch


def test_case_item_holds_the_cases_arrays(defaust_ci):
    c = load(defaust_ci, resolution="low")[2]
    item = case_item(c)
    assert set(item) == set(ITEM_ARRAYS) | set(ITEM_SCALARS) | set(ITEM_STRINGS)
    for k in ITEM_ARRAYS:
        assert item[k] is getattr(c, k)  # the case's arrays, not copies
    assert {k: int(item[k]) for k in ITEM_SCALARS} == {"subject": 0, "pose": 3, "n_dropped": 0, "seed": c.seed}
    assert all(item[k].shape == () and item[k].dtype == np.int64 for k in ITEM_SCALARS)
    assert (item["name"], item["resolution"], item["landmark_names"]) == ("s00_p03", "low", c.landmark_names)


def test_collate_keeps_meshes_of_different_sizes_as_lists_and_stacks_scalars(defaust_ci):
    low, high = load(defaust_ci, resolution="low"), load(defaust_ci, resolution="high")
    items = [case_item(low[0]), case_item(high[1]), case_item(low[3])]
    assert len(items[0]["V"]) != len(items[1]["V"])
    b = collate_cases(items)
    for k in ITEM_ARRAYS:
        assert isinstance(b[k], list) and [v is it[k] for v, it in zip(b[k], items)] == [True] * 3
    for k in ITEM_SCALARS:
        assert b[k].shape == (3,) and b[k].tolist() == [int(it[k]) for it in items]
    assert b["name"] == ["s00_p01", "s00_p02", "s00_p04"] and b["resolution"] == ["low", "high", "low"]


def test_collate_refuses_an_empty_batch_or_items_with_other_keys(defaust_ci):
    item = case_item(load(defaust_ci, resolution="low")[0])
    no_gt = {k: v for k, v in item.items() if k != "V_gt"}
    with pytest.raises(SShaDeError, match="item 1 has other keys than item 0 .V_gt."):
        collate_cases([item, no_gt])
    with pytest.raises(SShaDeError, match="no item"):
        collate_cases([])


def test_without_torch_the_module_imports_and_torch_dataset_says_what_to_install():
    code = """
import sys
class _Broken:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "torch":
            raise OSError("torch: libdemo.so.0: cannot open shared object file (simulated)")
sys.meta_path.insert(0, _Broken())
import numpy as np
from sshade.errors import SShaDeError
import defaust
b = defaust.collate_cases([{"pose": np.asarray(1)}, {"pose": np.asarray(2)}])
try:
    defaust.torch_dataset([])
except SShaDeError as e:
    print(b["pose"].tolist(), e)
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=subprocess_env(),
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == ("[1, 2] PyTorch cannot be imported (OSError: torch: libdemo.so.0: cannot open shared "
                                "object file (simulated)); it is the [neural] extra: pip install -e .[neural]")


def test_torch_dataset_without_torch_names_the_error_and_the_extra(defaust_ci, monkeypatch):
    monkeypatch.setattr(torch_data, "torch", None)
    monkeypatch.setattr(torch_data, "_TORCH_ERROR", "ImportError: No module named 'torch'")
    with pytest.raises(SShaDeError, match=r"^PyTorch cannot be imported \(ImportError: No module named 'torch'\); "
                                          r"it is the \[neural\] extra: pip install -e \.\[neural\]$"):
        torch_dataset(load(defaust_ci))


@pytest.mark.neural
def test_torch_dataset_refuses_a_float_dtype_that_is_not_one(defaust_ci):
    torch = _torch()
    for bad in ("float32", torch.int64, np.float32):
        with pytest.raises(SShaDeError, match="float_dtype must be None or a floating torch dtype"):
            torch_dataset(load(defaust_ci), float_dtype=bad)


@pytest.mark.neural
def test_dataloader_batches_equal_the_cases(defaust_ci):
    torch = _torch()
    from torch.utils.data import DataLoader
    cases = load(defaust_ci, resolution="high")
    ds = torch_dataset(cases, float_dtype=torch.float32)
    assert len(ds) == 4 and isinstance(ds, torch.utils.data.Dataset)
    batches = list(DataLoader(ds, batch_size=3, collate_fn=collate_cases))
    assert [len(b["V"]) for b in batches] == [3, 1]
    got = {name: (b, i) for b in batches for i, name in enumerate(b["name"])}
    for c in cases:
        b, i = got[c.name]
        assert (b["V"][i].dtype, b["F"][i].dtype, b["static"][i].dtype) == (torch.float32, torch.int64, torch.bool)
        np.testing.assert_array_equal(b["V"][i].numpy(), c.V.astype(np.float32))
        np.testing.assert_array_equal(b["V_gt"][i].numpy(), c.V_gt.astype(np.float32))
        for k in ("F", "handles", "static", "group"):
            np.testing.assert_array_equal(b[k][i].numpy(), getattr(c, k))
        assert int(b["pose"][i]) == c.pose and int(b["seed"][i]) == c.seed
    assert batches[0]["subject"].shape == (3,) and batches[0]["subject"].dtype == torch.int64
    item = ds[0]
    item["V"].add_(1.0)  # a tensor is a copy: the case's arrays stay as read
    np.testing.assert_array_equal(cases[0].V.astype(np.float32), ds[0]["V"].numpy())


@pytest.mark.neural
def test_dataloader_workers_read_an_archive_in_place(defaust_ci, tmp_path):
    torch = _torch()
    from torch.utils.data import DataLoader
    pack(defaust_ci, tmp_path / "ci.zip")
    cases = load(tmp_path / "ci.zip", resolution="low")
    cases[0]  # the parent has the archive open: the forked workers must open their own
    loader = DataLoader(torch_dataset(cases), batch_size=2, num_workers=2, collate_fn=collate_cases)
    names = []
    for b in loader:
        for i, name in enumerate(b["name"]):
            names.append(name)
            np.testing.assert_array_equal(b["targets"][i].numpy(), cases[name].targets)
            assert b["targets"][i].dtype == torch.float64
    assert names == list(cases.names)
