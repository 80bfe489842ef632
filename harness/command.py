"""Hydra command lines of the harness: a bad command line refused in one line, before any
work. :func:`hydra_main` composes the config with the command line's overrides through
Hydra's compose API first (:func:`precheck`: unknown key or group option, malformed
override, the command's own value check), so that nothing, not even a run folder, is made
before a refusal, then runs ``hydra.main``; :func:`run_command` is
:func:`sshade.command_errors.run_command` with Hydra's and OmegaConf's errors counted as a bad
configuration (``error: <one line>``, :func:`hydra_message`, status 2). Used by
``python -m eval``, ``eval.sweeps``, ``eval.tables``, ``eval.reproduce`` and the DeFAUST
builder (:mod:`defaust.cli`).
"""
from __future__ import annotations

import os
import sys

from sshade.command_errors import one_line
from sshade.command_errors import run_command as _run_command
from sshade.errors import SShaDeError

__all__ = ["run_command", "hydra_main", "precheck", "hydra_message", "config_error_types"]


def config_error_types() -> tuple:
    """Hydra's and OmegaConf's exception bases (a bad configuration, not a bug)."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException
    return HydraException, OmegaConfBaseException


def run_command(work, *, where=None) -> int:
    """:func:`sshade.command_errors.run_command` (its statuses: 0, 2, 130, 143) with Hydra's and
    OmegaConf's errors as ``error: <one line>`` lines (:func:`hydra_message`), status 2."""
    return _run_command(work, where=where, config_errors=config_error_types(), describe=hydra_message)


def hydra_message(e: BaseException) -> str:
    """Hydra's or OmegaConf's multi-line message as one line (the search path and the
    documentation link left out; the options of a config group listed inline)."""
    text = str(e).split("Config search path:")[0]
    out, opts = [], None
    for ln in (x.strip() for x in text.splitlines()):
        if not ln or ln.startswith("See https://hydra.cc") or ln.startswith(("full_key:", "object_type=")):
            continue
        if ln.startswith("Available options in"):
            out.append(ln)
            opts = []
        elif opts is not None:
            opts.append(ln)
        else:
            out.append(ln)
    msg = " ".join(out) + (" " + ", ".join(opts) if opts else "")
    cause = e.__cause__
    if cause is not None and cause is not e and not isinstance(cause, SShaDeError):
        first = next((x.strip() for x in str(cause).splitlines() if x.strip()), "")
        if first and first not in msg:
            msg += f" ({first})"
    return one_line(msg) or type(e).__name__




def _sweep_variants(overrides: list[str]) -> list[list[str]]:
    """For a multirun: the overrides with every sweep at its first value, then each other
    value of each sweep on its own (so every value is composed once, not the product)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    parsed = OverridesParser.create().parse_overrides(overrides)  # OverrideParseException if malformed
    base, sweeps = [], []
    for o in parsed:
        if not o.is_sweep_override():
            base.append(o.input_line)
            continue
        try:
            vals = [f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()]
        except Exception:  # noqa: BLE001 -- e.g. a glob sweep: Hydra's sweeper checks it
            continue
        if vals:
            sweeps.append((len(base), vals))
            base.append(vals[0])
    variants = [base]
    for i, vals in sweeps:
        for v in vals[1:]:
            variants.append(base[:i] + [v] + base[i + 1:])
    return variants[:64]


def _parse_each(overrides: list[str]) -> None:
    """SShaDeError naming the first override Hydra's grammar cannot parse."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import OverrideParseException
    parser = OverridesParser.create()
    for o in overrides:
        try:
            parser.parse_overrides([o])
        except OverrideParseException as e:
            raise SShaDeError(f"malformed override {o!r}: {hydra_message(e)} (see "
                              "https://hydra.cc/docs/advanced/override_grammar/basic)") from None


def precheck(conf_dir: str, argv: list[str], check=None) -> None:
    """Compose the config of a Hydra command line as ``hydra.main`` would, before it runs.

    Skipped for ``--help``, ``--hydra-help``, ``--info``, ``--shell-completion``,
    ``--experimental-rerun`` and another config (``-cp``/``-cn``/``-cd``). ``check(cfg)``
    (the command's value check) runs on a single run's config (not a multirun's, whose
    jobs check their own values, nor ``--cfg``).

    Raises
    ------
    SShaDeError for an unknown flag; Hydra's and OmegaConf's errors for an unknown key or
    group option or a malformed override; whatever ``check`` raises.
    """
    from hydra import compose, initialize_config_dir
    from hydra._internal.utils import get_args_parser
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode
    args, unknown = get_args_parser().parse_known_args(argv)
    if unknown:
        raise SShaDeError(f"unrecognized arguments: {' '.join(unknown)} (--help lists the options)")
    if (args.help or args.hydra_help or args.info or args.shell_completion or args.experimental_rerun
            or args.config_path or args.config_name or args.config_dir):
        return
    overrides = [str(o) for o in args.overrides]
    _parse_each(overrides)
    variants = _sweep_variants(overrides) if args.multirun else [overrides]
    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=conf_dir, version_base=None):
        cfgs = [compose(config_name="config", overrides=v, return_hydra_config=True) for v in variants]
    multirun = args.multirun or str(cfgs[0].hydra.get("mode", "")) == str(RunMode.MULTIRUN)
    if check is not None and not multirun and not args.cfg:
        from omegaconf import open_dict
        job = cfgs[0].copy()
        with open_dict(job):
            job.pop("hydra", None)  # the job's config, as the task function gets it
        check(job)


def hydra_main(task, conf_dir: str, *, argv=None, check=None, where=None) -> None:
    """Run the Hydra app ``task`` with config ``conf_dir/config.yaml`` on ``argv``
    (default ``sys.argv[1:]``): :func:`precheck`, then ``hydra.main``; returns on success,
    else exits with :func:`run_command`'s status (``SystemExit``). Hydra's exceptions reach
    :func:`run_command` (``HYDRA_FULL_ERROR`` is set while the app runs, so that
    ``hydra.main`` re-raises instead of printing them over several lines).

    Example::

        from harness.confdir import config_dir
        hydra_main(task, str(config_dir()))   # task(cfg) runs on the composed config
    """
    import hydra
    argv = list(sys.argv[1:] if argv is None else argv)

    def work():
        precheck(conf_dir, argv, check)
        old = os.environ.get("HYDRA_FULL_ERROR")
        os.environ["HYDRA_FULL_ERROR"] = "1"
        sys.argv = [sys.argv[0], *argv]
        try:
            hydra.main(version_base=None, config_path=conf_dir, config_name="config")(task)()
        finally:
            if old is None:
                os.environ.pop("HYDRA_FULL_ERROR", None)
            else:
                os.environ["HYDRA_FULL_ERROR"] = old
    rc = run_command(work, where=where)
    if rc:
        raise SystemExit(rc)
