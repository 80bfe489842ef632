"""Parameter sweeps of the evaluator (Hydra multirun) and their summary table.
Floor 6 of eval/ (above the commands, tests/test_layering.py); notes: docs/implementation.md.

Run a sweep (same config and overrides as ``python -m eval``; ``-m`` = multirun)::

    python -m eval.sweeps -m dataset.root=DIR methods=[SShaDe] sshade.n_low=500,1000,2000
    python -m eval.sweeps experiment=sweep dataset.root=...           # grid in conf/experiment/sweep.yaml
    python -m eval.sweeps -m ... hydra/launcher=slurm hydra.launcher.partition=NAME   # SLURM (submitit)
    python -m eval.sweeps aggregate outputs/sweeps/2025-01-01_12-00-00    # rebuild the table
    python -m eval.sweeps resume outputs/sweeps/2025-01-01_12-00-00       # re-run killed/failed/missing jobs
    python -m eval.sweeps --help                                          # this command's help (HELP)"""
from __future__ import annotations

import logging
import os
import socket
import sys
import time
import traceback
from pathlib import Path

from eval import app
from eval.config_check import plain
from eval.run.outdir import (
    MARKER,
    OutputDirError,
    alive,
    check_earlier_output,
    claim_output_dir,
    first_result_written,
)
from eval.run.paths import abs_path
from eval.run.pending_rows import share_stop
from eval.run.result_store import STORE_DIR
from eval.run.run_folder import claimed_run, overwrite_flag
from eval.run.spec import OutputOptions
from eval.sweeps.files import (
    KEEP,
    MANIFEST,
    RESUME_ENV,
    STATUS_FILE,
    job_dirs,
    now_iso,
    read_manifest,
    read_status,
    write_manifest,
    write_status,
)
from eval.sweeps.sweep_table import TABLE_CSV, TABLE_MD, aggregate_sweep, sweep_markdown, sweep_title
from harness.command import hydra_main, run_command
from harness.confdir import config_dir
from sshade.command_errors import ArgumentParser
from sshade.errors import SShaDeError

__all__ = ["HELP", "sweep_job", "AggregateSweepCallback", "sweep_points", "start_manifest", "finish_manifest",
           "grid_job_entries", "claim_sweep_dir", "release_sweep_dir", "end_unfinished_sweep", "resume_sweep",
           "main", "FIRST_RESULT"]

log = logging.getLogger("eval")

#: ``python -m eval.sweeps --help``: the command's own help (Hydra's would be the evaluator's)
HELP = """\
usage: python -m eval.sweeps [-m] [KEY=VALUE ...]      run a parameter sweep (Hydra multirun)
       python -m eval.sweeps resume SWEEP_DIR          run again a sweep's killed, failed and missing jobs
       python -m eval.sweeps aggregate SWEEP_DIR ...   rebuild sweep_table.{csv,md} of sweep folders

A parameter sweep of the evaluator (python -m eval): every combination of comma-separated
values is one job, the evaluator run into its own folder <sweep dir>/<job number>, its
outcome (done, partial, failed, killed, missing) in status.json there. A failing job is
recorded and the sweep goes on; at the end sweep_table.{csv,md} summarise the jobs.

How to sweep (-m = multirun):
  python -m eval.sweeps -m dataset=faust dataset.root=../shared/data/faust_reg dataset.limit=4 \\
      methods=[SShaDe] sshade.n_low=500,1000,2000 sshade.n_samplings=1,5
  python -m eval.sweeps experiment=sweep dataset=faust dataset.root=DIR  ready grid, no -m (conf/experiment/sweep.yaml)
  add hydra/launcher=joblib hydra.launcher.n_jobs=2                      jobs side by side
  add hydra/launcher=slurm hydra.launcher.partition=NAME                 jobs on SLURM

Output: hydra.sweep.dir=DIR (default outputs/multirun/<date_time>; experiment=sweep:
outputs/sweeps/<date_time>), one folder per job below it. Run again into DIR, a sweep
replaces the earlier one; with resume=true each job keeps its folder and its current
rows and computes only its stale and missing (case, method) pairs.

Every override of python -m eval works here (python -m eval --help lists the config
groups and keys; --hydra-help Hydra's options). Details: docs/sweeps.md.
"""
_RESUME_USAGE = "usage: python -m eval.sweeps resume SWEEP_DIR"
_HELP_FLAGS = ("-h", "--help")

_CALLBACK_KEY = "hydra.callbacks.sweep_aggregate"
_CALLBACK_TARGET = "eval.sweeps.sweep_command.AggregateSweepCallback"
#: Hydra names a job after its task function's module (here ``sweep_command``); a sweep's
#: jobs keep the name ``sweep`` (``hydra.job.name``: the SLURM job name, ``.hydra/hydra.yaml``)
_JOB_NAME = "hydra.job.name=sweep"
_MAX_ERROR = 2000


# ----------------------------------------------------------------------------- sweep.json
def sweep_points(config) -> list[list[str]] | None:
    """Every job's overrides of a multirun, in job-number order, expanded as Hydra's
    ``BasicSweeper`` does (``hydra.sweeper.params`` then the command-line task overrides,
    the Cartesian product of the sweeps). None for another sweeper or an override it
    cannot parse (then a missing job cannot be told from a job never asked for)."""
    try:
        from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
        from hydra.core.override_parser.overrides_parser import OverridesParser
        from omegaconf import OmegaConf
        sw = config.hydra.sweeper
        if not str(sw.get("_target_", "")).endswith("BasicSweeper") or sw.get("max_batch_size") is not None:
            return None
        params = sw.get("params", None)
        params = OmegaConf.to_container(params, resolve=False) if OmegaConf.is_config(params) else dict(params or {})
        conf = [f"{k}={v}" for k, v in params.items()] + [str(o) for o in config.hydra.overrides.task]
        batches = BasicSweeper.split_arguments(OverridesParser.create().parse_overrides(conf), None)
        return [[str(o) for o in job] for job in batches[0]]
    except Exception as e:  # noqa: BLE001 -- the table simply lists no missing job
        log.warning("cannot expand the sweep's grid (%s): jobs that never start will not be listed", e)
        return None


def start_manifest(config) -> Path:
    """Write (or, on a resume, update) ``<hydra.sweep.dir>/sweep.json`` before any job
    starts: the command (``argv``, ``cwd``) that :func:`resume_sweep` replays, the
    launcher, the grid (``points``: job number -> overrides, :func:`sweep_points`) and a
    ``runs`` entry (started, resume) that :func:`finish_manifest` closes."""
    d = Path(str(config.hydra.sweep.dir)).resolve()
    m = read_manifest(d) or {"created": now_iso(), "argv": sys.argv[1:], "cwd": os.getcwd(), "python": sys.executable}
    pts = sweep_points(config)
    if pts is not None:
        m["points"] = pts
    m["launcher"] = str(config.hydra.launcher.get("_target_", ""))
    m.setdefault("runs", []).append({"started": now_iso(), "argv": sys.argv[1:],
                                     "resume": os.environ.get(RESUME_ENV) == "1"})
    return write_manifest(d, m)


def finish_manifest(sweep_dir) -> None:
    """Mark the last run of ``sweep.json`` finished: from now on a job whose
    ``status.json`` still says ``running`` is reported as killed."""
    m = read_manifest(sweep_dir)
    if m and m.get("runs"):
        m["runs"][-1]["finished"] = now_iso()
        write_manifest(sweep_dir, m)


def _hydra_job() -> tuple[Path | None, list[str], int | None, str | None]:
    """(job output dir, task overrides, job number, sweep dir) of the running Hydra job."""
    try:
        from hydra.core.hydra_config import HydraConfig
        if not HydraConfig.initialized():
            return None, [], None, None
        hc = HydraConfig.get()
    except Exception:  # noqa: BLE001 -- outside Hydra
        return None, [], None, None
    out = hc.runtime.output_dir
    num = hc.job.get("num", None)
    from hydra.types import RunMode
    sweep = hc.sweep.dir if hc.mode == RunMode.MULTIRUN else None
    return (Path(out) if out else None, [str(o) for o in hc.overrides.task],
            None if num is None else int(num), None if sweep is None else str(sweep))


def _rows_status(out_dir: Path, res) -> dict:
    """done / partial / failed from the evaluator's result and its cases.csv."""
    if not isinstance(res, dict):
        return {"status": "done"}
    out = {k: res[k] for k in ("n_cases", "n_errors") if isinstance(res.get(k), (int, float))}
    n_err = int(out.get("n_errors", 0) or 0)
    if n_err == 0:
        return {"status": "done", **out}
    msgs, n_rows = [], None
    try:
        import pandas as pd
        df = pd.read_csv(out_dir / "cases.csv", keep_default_na=False)
        n_rows = len(df)
        bad = df[df["error"].astype(str).str.len() > 0]
        for (method, err), g in bad.groupby(["method", "error"], sort=False):
            msgs.append(f"{method}: {err} ({len(g)} case(s))")
    except Exception as e:  # noqa: BLE001 -- no cases.csv: keep the count only
        msgs.append(f"{n_err} failed (case, method) run(s) ({type(e).__name__} reading cases.csv)")
    status = "failed" if n_rows is not None and n_err >= n_rows else "partial"
    return {"status": status, "error": "; ".join(msgs)[:_MAX_ERROR], **out}


def sweep_job(cfg) -> dict:
    """Hydra task function of one sweep job: run the experiment into the job's folder,
    write ``status.json``, never raise (so the other jobs of the sweep go on).

    Returns the status dict (also written to ``<job dir>/status.json``).
    """
    from omegaconf import open_dict
    job_dir, overrides, num, sweep_dir = _hydra_job()
    if job_dir is None:
        job_dir = abs_path(cfg.get("out_dir", "outputs/sweep_job"))
    job_dir = Path(job_dir).resolve()
    with open_dict(cfg):
        cfg.out_dir = str(job_dir)  # every job writes its tables into its own folder
    if os.environ.get(RESUME_ENV) == "1":  # resume_sweep: keep what already has a result
        old = read_status(job_dir)
        if old and old.get("status") in KEEP and old.get("overrides") == overrides:
            log.info("job %s (%s): %s before, not run again", num, " ".join(overrides), old["status"])
            return {k: v for k, v in old.items() if k != "traceback"}
    status = {"status": "running", "job_num": num, "overrides": overrides, "out_dir": str(job_dir),
              "sweep_dir": sweep_dir, "host": socket.gethostname(), "pid": os.getpid(), "started": now_iso()}
    t0 = time.perf_counter()
    claimed = False
    try:
        # the job's folder (eval.run.outdir): new, or this job's earlier attempt; the job's
        # values are checked in it (app.run_experiment), a refusal recorded in its status.json
        output = OutputOptions(out_dir=str(job_dir), overwrite=cfg.get("overwrite", False),
                               resume=cfg.get("resume", False))
        with claimed_run(output, record=plain(cfg, resolve=False)):
            claimed = True
            write_status(job_dir, status)
            res = app.run_experiment(cfg)
            status.update(_rows_status(job_dir, res))
    except (Exception, SystemExit) as e:  # noqa: BLE001 -- record any failure, keep the sweep going
        msg = str(e) or type(e).__name__
        if not isinstance(e, SShaDeError):
            msg = f"{type(e).__name__}: {msg}"
        status.update(status="failed", error=msg[:_MAX_ERROR],
                      traceback="".join(traceback.format_exception(e))[-_MAX_ERROR:])
        log.error("job %s (%s) failed: %s", num, " ".join(overrides), msg)
        if isinstance(e, OutputDirError) and not claimed:
            print(f"job {num}: failed: {msg}", file=sys.stderr)
            return {k: v for k, v in status.items() if k != "traceback"}
    status.update(wall_s=round(time.perf_counter() - t0, 3), finished=now_iso())
    try:
        write_status(job_dir, status)
    except OSError as e:
        log.error("cannot write %s in %s: %s", STATUS_FILE, job_dir, e)
    if status["status"] != "done":
        level = "warning" if status["status"] == "partial" else "error"  # one prefix style
        print(f"{level}: job {num}: {status['status']}: {status.get('error', '')}", file=sys.stderr)
    return {k: v for k, v in status.items() if k != "traceback"}


# ----------------------------------------------------------------------------- the sweep folder
_sweep_claim: list = []  # (claim, its time in ns) of this process's sweep folder, until the sweep ends


def _job_number(job_dir: Path) -> int | None:
    """The job number of a job folder: its ``status.json``'s, else its name's (Hydra's default subdir)."""
    n = (read_status(job_dir) or {}).get("job_num")
    if isinstance(n, int) and not isinstance(n, bool):
        return n
    return int(job_dir.name) if job_dir.name.isdigit() else None


def _continuable(job_dir: Path) -> bool:
    """The job folder holds an evaluator output its job may continue
    (:func:`eval.run.outdir.check_earlier_output`); a job that failed before its first
    result left only its ``status.json``, which its job's claim would refuse."""
    try:
        check_earlier_output(job_dir, "eval", "")
    except OutputDirError:
        return False
    return True


def grid_job_entries(sweep_dir, n_jobs: int) -> list[str]:
    """The top-level entries of the sweep folder ``sweep_dir`` that a sweep of ``n_jobs``
    jobs (numbered 0 to n_jobs - 1) run again with ``resume=true`` continues: folders
    holding job folders (:func:`eval.sweeps.files.job_dirs`), every one of them numbered
    below ``n_jobs`` (:func:`_job_number`) and holding an evaluator output to continue
    (:func:`_continuable`). A job folder of another number, or of none, is no job of this
    sweep, and one without output has nothing to reuse: its entry is not continued (it is
    replaced, and its job, if any, starts in a new folder)."""
    d = Path(sweep_dir)
    out = []
    for e in sorted(os.listdir(d)) if d.is_dir() else []:
        q = d / e
        if e.startswith(".") or q.is_symlink() or not q.is_dir():
            continue
        jobs = job_dirs(q)
        if jobs and all((n := _job_number(j)) is not None and 0 <= n < n_jobs and _continuable(j) for j in jobs):
            out.append(e)
    return out


def _resumed_entries(pts: list | None, d: str) -> list[str]:
    """What a sweep with ``resume=true`` (run again into its folder, not
    :func:`resume_sweep`) continues of the earlier sweep in ``d``: the folders of the
    jobs of this sweep's grid ``pts`` (:func:`grid_job_entries`); every other entry of the
    earlier sweep (job folders beyond the grid, ``sweep.json``, ``sweep_table.*``) is
    replaced. A grid that cannot be expanded (``pts`` None, :func:`sweep_points`)
    continues nothing."""
    if pts is None:
        log.warning("resume=true: the sweep's grid cannot be expanded; the earlier job folders in %s are "
                    "replaced and every row computed again", d)
        return []
    return grid_job_entries(d, len(pts))


#: A sweep's first result: a (case, method) record one of its jobs stored, in a job folder
#: at any depth (``hydra.sweep.subdir``). Until one is written, the earlier sweep output it
#: replaces waits aside, put back if the sweep ends or is killed (``kill -9`` included: the
#: next claim of the folder recovers it) before.
FIRST_RESULT = f"**/{STORE_DIR}/*/*.json"


def claim_sweep_dir(config) -> None:
    """Claim ``hydra.sweep.dir`` for this sweep before any job starts
    (:func:`eval.run.outdir.claim_output_dir`, kind ``sweep``): a new or empty folder, or an
    earlier sweep's folder (its files are removed first; a resume, :data:`RESUME_ENV`,
    keeps them; ``resume=true`` keeps the folders of the jobs of this sweep's grid,
    :func:`_resumed_entries`, and replaces the rest); any other folder is refused unless
    ``overwrite=true``; the default dated folder gets a suffix when the name exists
    (``resume=true`` there is refused: no sweep to continue). On refusal: one ``error:``
    line, exit 2. The sweep's jobs write into folders of their own below it."""
    from omegaconf import open_dict

    d = str(config.hydra.sweep.dir)
    given = {str(o).lstrip("+~").split("=", 1)[0] for o in config.hydra.overrides.hydra}
    replay = os.environ.get(RESUME_ENV) == "1"
    fresh = "hydra.sweep.dir" not in given and not replay
    try:
        resume = overwrite_flag(config.get("resume", False))
        if resume and fresh:
            raise OutputDirError("resume=true continues a sweep in its folder: pass hydra.sweep.dir=DIR, the "
                                 "folder of the sweep to continue (the default is a new folder)")
        keep = True if replay else _resumed_entries(sweep_points(config), d) if resume else False
        c = claim_output_dir(d, "sweep", overwrite=overwrite_flag(config.get("overwrite", False)),
                             fresh=fresh, keep=keep, first_result=FIRST_RESULT)
    except SShaDeError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    if str(c.path) != str(Path(d).resolve()):  # a fresh name got a suffix: the jobs follow it
        with open_dict(config):
            config.hydra.sweep.dir = str(c.path)
            # each job's config is composed again from these overrides (Hydra's
            # load_sweep_config), so the new folder must be among them
            config.hydra.overrides.hydra.append(f"hydra.sweep.dir='{c.path}'")
    log.info(c.message)
    _sweep_claim.append((c, _claim_time_ns(c)))


def _claim_time_ns(c) -> int:
    """When the claim ``c`` took its folder, by the file system's own clock (ns): the
    earlier output's aside time where one was set aside, else the claim marker's
    modification time, so that a job's file written after the claim is never older, on a
    file system whose clock is coarser than ``time.time()``; 0 (everything counts) when
    neither can be read."""
    since = (c.aside or {}).get("since_ns")
    if isinstance(since, int) and not isinstance(since, bool):
        return since
    try:
        return (c.path / MARKER).stat().st_mtime_ns
    except OSError:
        return 0


def release_sweep_dir(status: str = "done") -> None:
    """Mark this process's sweep folder ended and release it (:func:`claim_sweep_dir`)."""
    while _sweep_claim:
        _sweep_claim.pop()[0].finish(status)


def _results_since(d: Path, t0_ns: int) -> bool:
    """Whether a job of the sweep folder ``d`` has a result modified at or after ``t0_ns``
    (ns, the file system's clock: :func:`_claim_time_ns`): a stored (case, method) record
    (the claim's own test, :data:`FIRST_RESULT`), or a final ``status.json`` (a job that
    failed before its first pair has only that)."""
    if first_result_written(d, FIRST_RESULT, t0_ns):
        return True
    for j in job_dirs(d):
        st = read_status(j)
        try:
            if st and st.get("status") != "running" and (j / STATUS_FILE).stat().st_mtime_ns >= t0_ns:
                return True
        except OSError:
            continue
    return False


def end_unfinished_sweep() -> None:
    """A sweep of this process stopped before its end (Ctrl-C, SIGTERM, an error after its
    folder was claimed): where its jobs wrote a result, the run is closed in ``sweep.json``
    (its job still ``running`` is then reported killed) and ``sweep_table.{csv,md}`` made
    again from the folders; where none did, the claim ends without a result, so the earlier
    sweep output it set aside is put back as it was and what it wrote goes (the job folders
    it continues stay: :meth:`eval.run.outdir.OutputClaim.finish`). Never raises."""
    while _sweep_claim:
        c, t0_ns = _sweep_claim.pop()
        try:
            if _results_since(c.path, t0_ns):
                finish_manifest(c.path)
                aggregate_sweep(c.path)
                c.finish("interrupted", result=True)
            else:
                c.finish("interrupted", drop_if_unused=_NO_RESULT)
        except Exception as e:  # noqa: BLE001 -- the command is already ending on its own error
            log.warning("could not close the stopped sweep in %s: %s", c.path, e)
            c.release()


#: A name no sweep writes: the claim of a sweep stopped without a result ends as unused.
_NO_RESULT = ".sshade-no-result"


# ----------------------------------------------------------------------------- Hydra callback
try:
    from hydra.experimental.callback import Callback as _Callback
except ImportError:  # pragma: no cover -- hydra-core is a dependency
    _Callback = object


class AggregateSweepCallback(_Callback):
    """Hydra callback
    (``hydra.callbacks.sweep_aggregate._target_=eval.sweeps.sweep_command.AggregateSweepCallback``):
    writes ``sweep.json`` (grid and command, :func:`start_manifest`) when a multirun
    starts, and builds ``sweep_table.{csv,md}`` when it ends."""

    def on_multirun_start(self, config, **kwargs) -> None:
        claim_sweep_dir(config)  # refuses a folder that is not this sweep's (exit 2), before any job
        try:
            start_manifest(config)
        except Exception as e:  # noqa: BLE001 -- a sweep without manifest still runs
            log.warning("cannot write %s: %s", MANIFEST, e)

    def on_job_end(self, config, job_return=None, **kwargs) -> None:
        """In a sweep, a sign of life of its folder once a job ended
        (:func:`eval.run.outdir.alive`): should the sweep be killed, the files its jobs
        wrote until then are its own, not files a person added after it died."""
        try:
            from hydra.core.hydra_config import HydraConfig
            from hydra.types import RunMode
            if HydraConfig.get().mode == RunMode.MULTIRUN:
                alive(abs_path(str(config.hydra.sweep.dir)))
        except Exception as e:  # noqa: BLE001 -- a sign of life never fails a job
            log.debug("no sign of life for the sweep folder: %s", e)

    def on_multirun_end(self, config, **kwargs) -> None:
        try:
            d = Path(str(config.hydra.sweep.dir))
            finish_manifest(d)
            df = aggregate_sweep(d)
        except Exception as e:  # noqa: BLE001 -- never fail a finished sweep over its summary
            log.warning("sweep aggregation failed: %s", e)
            print(f"error: sweep aggregation failed: {e}", file=sys.stderr)
            release_sweep_dir("done")
            return
        release_sweep_dir("done")
        print(sweep_markdown(df, title=sweep_title(d.resolve(), df)))
        print(f"wrote {TABLE_CSV}, {TABLE_MD} to {d.resolve()}")


# ----------------------------------------------------------------------------- CLI
def _aggregate_cli(args: list[str]) -> int:
    ap = ArgumentParser(prog="python -m eval.sweeps aggregate",
                                 description="Summarise sweep folders into sweep_table.{csv,md}.")
    ap.add_argument("dirs", nargs="+", help="sweep folder(s) (hydra.sweep.dir)")
    ap.add_argument("--no-write", action="store_true", help="print only, write nothing")
    a = ap.parse_args(args)
    rc = 0
    for d in a.dirs:
        try:
            df = aggregate_sweep(d, write=not a.no_write)
        except SShaDeError as e:
            print(f"error: {e}", file=sys.stderr)
            rc = 2
            continue
        print(sweep_markdown(df, title=sweep_title(Path(d).resolve(), df)))
        if not a.no_write:
            print(f"wrote {TABLE_CSV}, {TABLE_MD} to {Path(d).resolve()}")
    return rc


def _resume_argv(man: dict, sweep_dir: Path) -> list[str]:
    """The sweep's command line with ``hydra.sweep.dir`` pinned to ``sweep_dir`` (the
    original may hold a ``${now:...}`` default or another spelling of the folder)."""
    argv = [str(a) for a in man.get("argv") or []]
    argv = [a for a in argv if a.lstrip("+~").split("=", 1)[0] != "hydra.sweep.dir"]
    # the callback main adds, recorded under the module path of its day: main adds today's
    argv = [a for a in argv if not (a.lstrip("+~").startswith(f"{_CALLBACK_KEY}._target_=")
                                    and a.endswith(".AggregateSweepCallback"))]
    if not any(a in ("-m", "--multirun") for a in argv):
        argv.insert(0, "-m")
    return [*argv, f"hydra.sweep.dir={sweep_dir}"]


def resume_sweep(sweep_dir) -> int:
    """Run again the killed, failed and missing jobs of a sweep, with the same command
    (config, overrides, launcher) as recorded in ``sweep.json``, into the same folders;
    the jobs that are done or partial are not run again (:data:`RESUME_ENV`: the SLURM
    launcher does not submit them, the job function of the other launchers returns at
    once). ``sweep_table.{csv,md}`` are rebuilt at the end.

    Returns the exit status: 0 (also when nothing is left to run), 2 when the folder
    holds no ``sweep.json`` (a sweep not started by ``python -m eval.sweeps``).

    Raises
    ------
    SShaDeError when ``sweep_dir`` is not a folder.
    """
    d = Path(sweep_dir).expanduser().resolve()
    if not d.is_dir():
        raise SShaDeError(f"sweep folder not found: {d}")
    man = read_manifest(d)
    if not man or not man.get("argv") and not man.get("points"):
        print(f"error: {d / MANIFEST} not found or empty: only sweeps started by python -m eval.sweeps "
              "can be resumed", file=sys.stderr)
        return 2
    df = aggregate_sweep(d)
    todo = df[~df["status"].isin(KEEP)]
    if todo.empty:
        print(sweep_markdown(df, title=sweep_title(d, df)))
        print(f"resume: every job of {d} is done or partial; nothing to run")
        return 0
    print(f"resume: running again {len(todo)} of {len(df)} job(s): "
          + ", ".join(f"{j} ({s})" for j, s in zip(todo["job"], todo["status"])), flush=True)
    cwd = man.get("cwd") or os.getcwd()
    os.environ[RESUME_ENV] = "1"  # inherited by the jobs (SLURM exports the environment)
    old = os.getcwd()
    try:
        os.chdir(cwd)  # relative paths of the command (dataset.root, ...) mean what they meant
        main(_resume_argv(man, d))
    finally:
        os.chdir(old)
        os.environ.pop(RESUME_ENV, None)
    return 0


def main(argv: list[str] | None = None) -> None:
    """``python -m eval.sweeps [hydra args and overrides]``, ``... aggregate DIR...`` or
    ``... resume DIR`` (:func:`resume_sweep`); ``--help`` prints :data:`HELP` and exits 0.

    Exits with 0 once every job has an outcome; 2 after one ``error: ...`` line for a bad
    command line (an unknown key or config group option, a malformed override: refused
    before any job starts, :func:`harness.command.precheck`) or an OSError; 130 after
    ``interrupted`` on Ctrl-C.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in ("aggregate", "resume") and any(a in _HELP_FLAGS for a in argv):
        print(HELP, end="")
        raise SystemExit(0)
    if argv and argv[0] == "aggregate":
        raise SystemExit(run_command(lambda: _aggregate_cli(argv[1:]), where=argv[1] if len(argv) > 1 else None))
    try:
        share_stop()  # python -m eval.reproduce --budget: one stop for every job of the sweep
    except SShaDeError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    if argv and argv[0] == "resume":
        if len(argv) == 2 and argv[1] in _HELP_FLAGS:
            print(f"{_RESUME_USAGE}\n\nRun again the killed, failed and missing jobs of the sweep in SWEEP_DIR "
                  "with its recorded command,\ninto the same folders; sweep_table.{csv,md} are rebuilt at the end.")
            raise SystemExit(0)
        if len(argv) != 2 or argv[1].startswith("-"):
            print(f"error: {_RESUME_USAGE} (python -m eval.sweeps --help)", file=sys.stderr)
            raise SystemExit(2)
        raise SystemExit(run_command(lambda: resume_sweep(argv[1]), where=argv[1]))
    if any(a in ("-m", "--multirun") for a in argv) and not any(_CALLBACK_KEY in a for a in argv):
        argv.append(f"++{_CALLBACK_KEY}._target_={_CALLBACK_TARGET}")
    if not any(a.lstrip("+~").startswith("hydra.job.name=") for a in argv):
        argv.append(_JOB_NAME)
    try:
        hydra_main(sweep_job, config_dir(), argv=argv)
    finally:
        end_unfinished_sweep()  # a sweep that ended normally released its folder already
