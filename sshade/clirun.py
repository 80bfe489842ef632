"""What every command does around its work: one ``error: ...`` line, no traceback.

Shared by ``python -m eval``, ``eval.sweep``, ``eval.tables``, ``eval.reproduce``,
``defaust`` and ``sshade deform`` (their ``main()``):

* :func:`run_command` runs the work and maps what escapes it to an exit status:
  :class:`~sshade.errors.SShaDeError`, Hydra's and OmegaConf's errors -> ``error: <one
  line>``, status 2; :class:`OSError` (disk full, read-only folder, permission denied)
  -> ``error: cannot write <file>: <reason>``, status 2; Ctrl-C -> ``interrupted``,
  status 130; SIGTERM (``kill``, ``timeout``, SLURM's ``scancel``) the same way
  (:class:`Terminated`, a KeyboardInterrupt, so that the run is stopped and marked
  interrupted as on Ctrl-C), status 143. Anything else is a bug and keeps its traceback.
* :func:`hydra_main` composes the config with the command line's overrides through
  Hydra's compose API first (:func:`precheck`: unknown key, unknown group option,
  malformed override, and the command's own value check), so a bad command line is
  refused in one line before Hydra makes a run folder; then runs ``hydra.main``.
* :class:`ArgumentParser`: argparse whose usage errors are one ``error: ...`` line.
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
from pathlib import Path

from .errors import SShaDeError

__all__ = ["INTERRUPTED", "TERMINATED", "Terminated", "run_command", "hydra_main", "precheck", "os_error_line",
           "one_line", "ArgumentParser"]

INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C
TERMINATED = 143  # 128 + SIGTERM
_TMP = re.compile(r"^\.(?P<name>.+)\.[^.]+\.tmp$")  # sshade.mesh.io.atomic_write's temporary files


def one_line(text) -> str:
    """``text`` with every run of whitespace (newlines included) made one space."""
    return " ".join(str(text).split())


def os_error_line(e: OSError, where=None) -> str:
    """``error: cannot write <file>: <strerror>`` for an OSError of a run.

    ``<file>`` is the error's file name, an atomic writer's temporary ``.NAME.XXXX.tmp``
    given as the ``NAME`` it was to become, else ``where`` (the command's output), else
    left out.
    """
    name = e.filename if e.filename is not None else where
    if name is not None:
        p = Path(os.fsdecode(name))
        m = _TMP.match(p.name)
        name = str(p.with_name(m.group("name")) if m else p)
    reason = e.strerror or one_line(e) or type(e).__name__
    return f"error: cannot write {name}: {reason}" if name else f"error: cannot write: {reason}"


def _config_error_types() -> tuple:
    types: list = [SShaDeError]
    try:
        from hydra.errors import HydraException
        from omegaconf.errors import OmegaConfBaseException
        types += [HydraException, OmegaConfBaseException]
    except ImportError:  # pragma: no cover -- sshade deform runs without Hydra
        pass
    return tuple(types)


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


class Terminated(KeyboardInterrupt):
    """Raised by :func:`run_command`'s SIGTERM handler: a KeyboardInterrupt, so that
    whatever stops and records a run on Ctrl-C does so on SIGTERM too; the command then
    exits with :data:`TERMINATED`."""
    signal_name = "SIGTERM"


_SIGINT = {"seen": False, "said": False, "status": INTERRUPTED}


def _on_sigint(signum, frame):
    """SIGINT handler of :func:`run_command`: as Python's own (KeyboardInterrupt), and
    remembered, so an interrupt that a library swallows (trimesh wraps its optional
    imports in ``except BaseException``) still ends the command as interrupted."""
    _SIGINT["seen"] = True
    raise KeyboardInterrupt


def _on_sigterm(signum, frame):
    """SIGTERM handler of :func:`run_command`: :class:`Terminated`, remembered as
    :func:`_on_sigint` does."""
    _SIGINT.update(seen=True, status=TERMINATED)
    raise Terminated


def _interrupted(e: BaseException | None = None) -> int:
    if isinstance(e, Terminated):
        _SIGINT["status"] = TERMINATED
    if not _SIGINT["said"]:  # once, also when nested run_command calls see it
        _SIGINT["said"] = True
        _say("interrupted")
    return _SIGINT["status"]


def _install_sigint():
    """Install :func:`_on_sigint` when SIGINT has Python's default handler (not ignored)
    and :func:`_on_sigterm` when SIGTERM has the default action, in the main thread;
    returns the handlers to restore ({} when nothing was installed)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    old = {}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        old[signal.SIGINT] = signal.default_int_handler
    if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        old[signal.SIGTERM] = signal.SIG_DFL
    if old:
        _SIGINT.update(seen=False, said=False, status=INTERRUPTED)
    for s in old:
        signal.signal(s, _on_sigint if s == signal.SIGINT else _on_sigterm)
    return old


def run_command(work, *, where=None) -> int:
    """Run ``work()`` (returning an exit status or None) and map what escapes it.

    Returns
    -------
    int: ``work``'s status (None or a non-int -> 0); 2 after one ``error: ...`` line on
    stderr for a bad input or configuration (:class:`SShaDeError`, Hydra's and
    OmegaConf's errors) or an :class:`OSError` (:func:`os_error_line`, ``where`` naming
    the output when the error names no file); 130 after ``interrupted`` on Ctrl-C (also
    when a library swallowed the KeyboardInterrupt), 143 after ``interrupted`` on
    SIGTERM (:class:`Terminated`). ``SystemExit`` passes through; any other exception is
    a bug and propagates with its traceback.
    """
    old = _install_sigint()
    try:
        rc = work()
        if _SIGINT["seen"]:
            return _interrupted()
        return rc if isinstance(rc, int) and not isinstance(rc, bool) else 0
    except KeyboardInterrupt as e:
        return _interrupted(e)
    except _config_error_types() as e:  # first: Hydra's MissingConfigException is an IOError
        if _SIGINT["seen"]:
            return _interrupted()
        _say(f"error: {one_line(e) if isinstance(e, SShaDeError) else hydra_message(e)}")
        return 2
    except OSError as e:
        if _SIGINT["seen"]:
            return _interrupted()
        _say(os_error_line(e, where))
        return 2
    except Exception:
        if _SIGINT["seen"]:  # e.g. a swallowed interrupt resurfacing as another error
            return _interrupted()
        raise
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def _say(line: str) -> None:
    try:
        sys.stdout.flush()
    except (OSError, ValueError):
        pass
    print(line, file=sys.stderr, flush=True)


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
    ``hydra.main`` re-raises instead of printing them over several lines)."""
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


class ArgumentParser(argparse.ArgumentParser):
    """argparse whose usage errors are one ``error: <message> (<prog> --help)`` line and
    exit status 2 (argparse's own print the usage first, then ``<prog>: error: ...``)."""

    def error(self, message):  # noqa: D102 -- argparse hook
        print(f"error: {one_line(message)} ({self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)
