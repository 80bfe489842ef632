"""The ``export`` experiment (``python -m eval experiment=export dataset=... out_dir=DIR``):
every case of the configured dataset written in the exchange layout
(:mod:`eval.exchange.layout`), for a method that runs outside this harness; its results
come back through ``experiment=score`` (:mod:`eval.exchange.scored`). No method runs."""
from __future__ import annotations

import dataclasses
import logging

from eval import datasets
from eval.exchange.layout import INDEX, write_export
from eval.experiments.experiment_registry import register_experiment
from eval.run.jsonsafe import json_safe
from eval.run.paths import abs_path
from eval.run.result_store import case_identity
from eval.run.runinfo import collect_runinfo, write_runinfo
from eval.run.spec import EvalSpec
from eval.run.subset import take_sample
from sshade.errors import SShaDeError

__all__ = ["run_export"]

log = logging.getLogger("eval")


def run_export(spec: EvalSpec) -> dict:
    """Write the cases of ``spec.dataset`` into ``spec.output.out_dir`` (already claimed by
    :func:`eval.app.run_experiment`): one folder per case and :data:`eval.exchange.layout.INDEX`.

    Returns
    -------
    dict: ``out_dir`` (Path), ``paths`` (``index`` and ``run.json``), ``n_cases``.

    Raises
    ------
    SShaDeError when the dataset has no case or cannot be read (before any file is written).
    """
    ds = spec.dataset
    root = datasets.dataset_root(ds)   # a DeFAUST is built first when it must be
    cases, rule = take_sample(datasets.load_cases(ds.name, root, ds.options), ds.sample, ds.sample_seed)
    if not cases:
        raise SShaDeError(f"dataset {ds.name} at {root}: no case to export")
    out = abs_path(spec.output.out_dir)
    meta = {"name": ds.name, "root": str(root), "seed": json_safe(ds.seed), "options": json_safe(_options(ds.options)),
            "identities": {c.name: case_identity(c, dataset=ds.name, seed=ds.seed) for c in cases}}
    if ds.sample is not None:
        meta["sample"] = {"k": ds.sample, "seed": ds.sample_seed, "rule": rule}
    index = write_export(out, cases, dataset=meta)
    log.info("exported %d case(s) of %s to %s (%s; %s)", len(cases), ds.name, out, INDEX, rule)
    info = collect_runinfo(spec.record(), seeds={"dataset": json_safe(ds.seed)},
                           extra={"status": "done", "out_dir": str(out), "n_cases": len(cases)})
    write_runinfo(out / "run.json", info)
    return {"out_dir": out, "paths": {"index": index, "run.json": out / "run.json"}, "n_cases": len(cases)}


def _options(options) -> dict:
    """What the index records of the dataset's options: every key but ``name`` and ``root``
    (recorded beside them), as plain values."""
    return {k: v for k, v in dataclasses.asdict(options).items() if k not in ("name", "root")}


def export_options(values) -> None:
    """The export's own check, of the ``dataset`` section (plain values): a dataset with a
    name (its own keys are checked by its options object at the door); SShaDeError otherwise. The
    export has no options of its own (None)."""
    if values is None or not str(values.get("name", "") or ""):
        raise SShaDeError("experiment=export needs a dataset: pass dataset=faust|defaust|shapes and dataset.root=DIR")
    return None


register_experiment("export", run_export, section="dataset", options=export_options)
