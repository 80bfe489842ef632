"""What every command does around its work: one ``error: ...`` line, no traceback. Used by
``python -m sshade deform|animate|view|warmup`` and, through
:func:`harness.command.run_command`, by every command of the harness.

* :func:`run_command`: SShaDeError -> ``error: <one line>``, status 2; OSError ->
  ``error: cannot write <file>: <reason>``, 2; Ctrl-C -> ``interrupted``, 130; SIGTERM
  (:class:`Terminated`, a KeyboardInterrupt) the same way, 143; anything else is a bug
  and keeps its traceback.
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

__all__ = ["INTERRUPTED", "TERMINATED", "Terminated", "run_command", "os_error_line", "one_line", "ArgumentParser"]

INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C
TERMINATED = 143  # 128 + SIGTERM
_TMP = re.compile(r"^\.(?P<name>.+)\.[^.]+\.tmp$")  # sshade.files.atomic_write's temporary files


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


def run_command(work, *, where=None, config_errors=(), describe=None) -> int:
    """Run ``work()`` (returning an exit status or None) and map what escapes it.

    Returns
    -------
    int: ``work``'s status (None or a non-int -> 0); 2 after one ``error: ...`` line on
    stderr for a bad input or configuration (:class:`SShaDeError`, or one of the
    ``config_errors`` types, told in one line by ``describe(e)``: the harness's command
    runner passes Hydra's and OmegaConf's, :func:`harness.command.run_command`) or an
    :class:`OSError` (:func:`os_error_line`, ``where`` naming
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
    except (SShaDeError, *config_errors) as e:  # first: Hydra's MissingConfigException is an IOError
        if _SIGINT["seen"]:
            return _interrupted()
        _say(f"error: {one_line(e) if isinstance(e, SShaDeError) or describe is None else describe(e)}")
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


class ArgumentParser(argparse.ArgumentParser):
    """argparse whose usage errors are one ``error: <message> (<prog> --help)`` line and
    exit status 2 (argparse's own print the usage first, then ``<prog>: error: ...``)."""

    def error(self, message):  # noqa: D102 -- argparse hook
        print(f"error: {one_line(message)} ({self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)
