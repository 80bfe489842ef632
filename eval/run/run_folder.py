"""One evaluator (or sweep) run in its claimed output folder: :func:`claimed_run` claims the
folder (:func:`eval.run.outdir.claim_output_dir`), records the run's config and Hydra's in
``.hydra/``, logs into the folder and, at the end, marks it done, failed or interrupted;
:func:`overwrite_flag` reads the ``overwrite``/``resume`` switches. Floor 0 of eval/
(eval/run/); notes: docs/outputs.md."""
from __future__ import annotations

import contextlib
import datetime as _dt
import os
from pathlib import Path

from eval.run.outdir import OutputClaim, OutputDirError, claim_output_dir, resume_command
from eval.run.runinfo import read_runinfo, write_runinfo
from eval.run.spec import OutputOptions

__all__ = ["claimed_run", "overwrite_flag"]

_claimed: dict[str, OutputClaim] = {}  # folders this process claimed and still writes into
_LOG_FORMAT = "[%(asctime)s][%(name)s][%(levelname)s] - %(message)s"


def _hydra_record(out: Path, record) -> None:
    """``out/.hydra/{config,hydra,overrides}.yaml``, as Hydra writes them (Hydra itself
    writes nothing: ``hydra.output_subdir`` is null, so nothing lands before the claim);
    ``record`` is the run's config, unresolved (``config.yaml``; None: not written)."""
    from omegaconf import OmegaConf
    try:
        from hydra.core.hydra_config import HydraConfig
        hc = HydraConfig.get() if HydraConfig.initialized() else None
    except ImportError:  # pragma: no cover -- hydra-core is a dependency
        hc = None
    d = out / ".hydra"
    d.mkdir(exist_ok=True)
    if record is not None:
        OmegaConf.save(OmegaConf.create(dict(record)), d / "config.yaml", resolve=False)
    if hc is not None:
        OmegaConf.save(OmegaConf.create({"hydra": hc}), d / "hydra.yaml", resolve=False)
        OmegaConf.save(OmegaConf.create(list(hc.overrides.task)), d / "overrides.yaml")


def _end_runinfo(out: Path, status: str, error: str) -> None:
    """A ``run.json`` still saying ``running`` gets the run's real end (failed,
    interrupted) and the error: it never stays ``running`` after a failure."""
    info = read_runinfo(out)
    if info.get("status") == "running":
        ended = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        info.update(status=status, error=error[:2000], ended_utc=ended)
        with contextlib.suppress(OSError):
            write_runinfo(out / "run.json", info)


@contextlib.contextmanager
def claimed_run(output: OutputOptions, *, record=None, kind: str = "eval", fresh: bool = False,
                log_name: str = "eval.log"):
    """Run one experiment in its claimed output folder ``output.out_dir``.

    Claims the folder (:func:`claim_output_dir`, ``output.overwrite``; ``output.resume``
    true: ``keep``, the earlier output of the same kind is continued), records the run's
    config ``record`` (unresolved, its ``out_dir`` the folder claimed: a fresh name may have
    gained a suffix) and Hydra's in ``.hydra/``, logs into ``out/eval.log``; at the end marks
    the folder done, failed or interrupted (``run.json`` too) and releases it. A run that
    ends before writing ``run.json`` (refused before any work: an unknown method, a missing
    dataset) leaves nothing: what it wrote is removed, with the folder and its parents when
    this run created them (:meth:`OutputClaim.finish`). Nested use on a folder this process
    already claimed does nothing.

    Yields
    ------
    OutputClaim (or None when the folder was already claimed by this process).

    Raises
    ------
    OutputDirError before any work (see :func:`claim_output_dir`).
    """
    import logging

    out_dir = output.out_dir
    target = os.path.abspath(Path(str(out_dir)).expanduser()) if out_dir else ""
    if target and target in _claimed:
        yield None
        return
    # resume=true (the evaluator's result store, eval/run/result_store.py): the earlier output is continued,
    # not replaced
    claim = claim_output_dir(out_dir, kind, overwrite=overwrite_flag(output.overwrite), fresh=fresh,
                             keep=overwrite_flag(output.resume), first_result="run.json", own=(log_name, ".hydra"))
    _claimed[str(claim.path)] = claim
    handler = None
    status, error = "failed", ""
    try:
        logging.getLogger("eval").info(claim.message)
        _hydra_record(claim.path, None if record is None else {**record, "out_dir": str(claim.path)})
        handler = logging.FileHandler(claim.path / log_name)
        handler.setFormatter(logging.Formatter(_LOG_FORMAT))
        logging.getLogger().addHandler(handler)
        yield claim
        status = "done"
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (sshade.command_errors.Terminated)
        status, error = "interrupted", f"interrupted ({getattr(e, 'signal_name', 'Ctrl-C')})"
        if kind == "eval" and (claim.path / "run.json").is_file():
            logging.getLogger("eval").warning("interrupted; the finished runs are stored; to continue: %s",
                                              resume_command(claim.path))
        raise
    except BaseException as e:
        error = " ".join(str(e).split()) or type(e).__name__
        raise
    finally:
        if handler is not None:
            logging.getLogger().removeHandler(handler)
            handler.close()
        _end_runinfo(claim.path, status, error)
        _claimed.pop(str(claim.path), None)
        claim.finish(status, drop_if_unused="run.json" if status != "done" else None)


def overwrite_flag(v) -> bool:
    """``overwrite`` as a bool (true/false, yes/no, 1/0). Raises OutputDirError otherwise."""
    if isinstance(v, bool):
        return v
    s = str(v).strip().lower()
    if s in ("true", "yes", "1"):
        return True
    if s in ("false", "no", "0", "none", "null", ""):
        return False
    raise OutputDirError(f"overwrite must be true or false, got {v!r}")
