"""The ``export`` experiment (``python -m eval experiment=export dataset=... out_dir=DIR``):
every case of the configured dataset written in the exchange layout
(:mod:`eval.exchange.layout`), for a method that runs outside this harness; its results
come back through ``experiment=score`` (:mod:`eval.exchange.scored`). No method runs."""
from __future__ import annotations

import logging

from eval import datasets
from eval.exchange.layout import INDEX, write_export
from eval.experiments.experiment_registry import register_experiment
from eval.run.jsonsafe import json_safe
from eval.run.paths import abs_path
from eval.run.result_store import case_identity
from eval.run.runinfo import collect_runinfo, write_runinfo
from sshade.errors import SShaDeError

__all__ = ["run_export"]

log = logging.getLogger("eval")


def run_export(cfg) -> dict:
    """Write the cases of ``cfg.dataset`` into ``cfg.out_dir`` (already claimed by
    :func:`eval.app.run_experiment`): one folder per case and :data:`eval.exchange.layout.INDEX`.

    Returns
    -------
    dict: ``out_dir`` (Path), ``paths`` (``index`` and ``run.json``), ``n_cases``.

    Raises
    ------
    SShaDeError when the dataset has no case or cannot be read (before any file is written).
    """
    from omegaconf import OmegaConf
    ds = cfg.dataset
    name = str(ds.get("name", ""))
    root = datasets.dataset_root(cfg)   # a DeFAUST is built first when it must be
    cases = datasets.load_cases(name, root, **datasets.dataset_options(ds))
    if not cases:
        raise SShaDeError(f"dataset {name} at {root}: no case to export")
    out = abs_path(cfg.out_dir)
    seed = ds.get("seed")
    meta = {"name": name, "root": str(root), "seed": json_safe(seed),
            "options": json_safe(datasets.dataset_options(ds)),
            "identities": {c.name: case_identity(c, dataset=name, root=root, seed=seed) for c in cases}}
    index = write_export(out, cases, dataset=meta)
    log.info("exported %d case(s) of %s to %s (%s)", len(cases), name, out, INDEX)
    info = collect_runinfo(OmegaConf.to_container(cfg, resolve=True), seeds={"dataset": json_safe(seed)},
                           extra={"status": "done", "out_dir": str(out), "n_cases": len(cases)})
    write_runinfo(out / "run.json", info)
    return {"out_dir": out, "paths": {"index": index, "run.json": out / "run.json"}, "n_cases": len(cases)}


def check_export(cfg) -> None:
    """The export's config before any work: a dataset with a name (its own keys are
    checked by the dataset's check); SShaDeError otherwise."""
    ds = cfg.get("dataset")
    if ds is None or not str(ds.get("name", "") or ""):
        raise SShaDeError("experiment=export needs a dataset: pass dataset=faust|defaust|shapes and dataset.root=DIR")


register_experiment("export", run_export, check=check_export)
