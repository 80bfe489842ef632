"""Sweeps on SLURM that end, whatever happens to their jobs.
Floor 4 of eval/ (eval/sweeps/, tests/test_layering.py); notes: docs/implementation.md.

The Hydra plugin class is ``hydra_plugins.sshade_sweep_launcher.SweepSlurmLauncher``
(Hydra only loads launchers from the ``hydra_plugins`` package), selected by
``hydra/launcher=slurm`` (``conf/hydra/launcher/slurm.yaml``)."""
from __future__ import annotations

import logging
import os
from pathlib import Path

from eval.sweeps.files import KEEP, RESUME_ENV, job_dirs, read_status, record_outcome
from harness.slurm_jobs import (
    ACTIVE_STATES,
    JobOutcome,
    SlurmQueryError,
    expand_job_ids,
    killed_message,
    slurm_states,
    state_text,
    wait_for_jobs,
)

__all__ = ["ACTIVE_STATES", "SlurmQueryError", "slurm_states", "expand_job_ids", "JobOutcome",
           "wait_for_jobs", "TolerantLauncherMixin"]  # the first six: harness/slurm_jobs.py

log = logging.getLogger(__name__)


class TolerantLauncherMixin:
    """``launch`` of hydra-submitit-launcher's launchers (same submission: one job array,
    the plugin's executor parameters), waiting with :func:`wait_for_jobs` instead of
    ``job.results()``. Mixed in before ``SlurmLauncher``; its own settings (``poll_s``,
    ``grace_polls``, ``unreachable_s``) are taken out of the executor parameters."""

    OWN_KEYS = {"poll_s": 10.0, "grace_polls": 2, "unreachable_s": 1800.0}

    def __init__(self, **params) -> None:
        own = {k: params.pop(k, None) for k in self.OWN_KEYS}
        self.wait_params = {k: v if own[k] is None else type(v)(own[k]) for k, v in self.OWN_KEYS.items()}
        super().__init__(**params)

    # the submission, as hydra_submitit_launcher.BaseSubmititLauncher.launch (1.2) does it
    def _executor(self):
        import submitit
        from hydra_plugins.hydra_submitit_launcher.config import BaseQueueConf
        from omegaconf import OmegaConf
        init = {"folder": self.params["submitit_folder"]}
        init.update({f"{self._EXECUTOR}_{k}": v for k, v in self.params.items() if k == "max_num_timeout"})
        executor = submitit.AutoExecutor(cluster=self._EXECUTOR, **init)
        base = set(OmegaConf.structured(BaseQueueConf).keys())
        executor.update_parameters(**{k if k in base else f"{self._EXECUTOR}_{k}": v for k, v in self.params.items()
                                      if k not in ("max_num_timeout", "submitit_folder")})
        return executor

    def launch(self, job_overrides, initial_job_idx):
        """Submit the jobs (those without a done/partial result in a resumed sweep) and
        wait until each has an outcome; returns one ``JobReturn`` per job, all
        ``COMPLETED`` (a job's failure is in its return value and ``status.json``)."""
        from hydra.core.singleton import Singleton
        from hydra.core.utils import JobReturn, JobStatus, filter_overrides

        assert self.config is not None
        sweep_dir = Path(str(self.config.hydra.sweep.dir))
        sweep_dir.mkdir(parents=True, exist_ok=True)
        if "mode" in self.config.hydra.sweep:
            os.chmod(sweep_dir, mode=int(str(self.config.hydra.sweep.mode), 8))
        log.info("Submitit '%s' sweep output dir : %s", self._EXECUTOR, self.config.hydra.sweep.dir)
        keep = _kept_jobs(sweep_dir) if os.environ.get(RESUME_ENV) == "1" else {}
        returns: list = [None] * len(job_overrides)
        params, where = [], []
        for pos, overrides in enumerate(job_overrides):
            idx = initial_job_idx + pos
            st = keep.get(idx)
            if st is not None and st.get("overrides") == list(overrides):
                log.info("\t#%d : %s (%s before: not submitted)", idx, " ".join(filter_overrides(overrides)),
                         st["status"])
                returns[pos] = JobReturn(overrides=list(overrides), status=JobStatus.COMPLETED, _return_value=st)
                continue
            log.info("\t#%d : %s", idx, " ".join(filter_overrides(overrides)))
            params.append((list(overrides), "hydra.sweep.dir", idx, f"job_id_for_{idx}", Singleton.get_state()))
            where.append((pos, idx))
        if not params:
            return returns
        jobs = self._executor().map_array(self, *zip(*params))
        log.info("submitted %d job(s): %s", len(jobs), ", ".join(str(j.job_id) for j in jobs))

        def report(i, outcome: JobOutcome):
            pos, idx = where[i]
            jid = str(jobs[i].job_id)
            if outcome.kind == "result":
                ret = outcome.value
                if getattr(ret, "status", None) == JobStatus.FAILED:  # the task raised (not sweep_job)
                    err = f"{type(ret._return_value).__name__}: {ret._return_value}"
                    record_outcome(sweep_dir, idx, "failed", err, slurm_job_id=jid)
                    ret = JobReturn(overrides=list(job_overrides[pos]), status=JobStatus.COMPLETED,
                                    _return_value={"status": "failed", "error": err})
                returns[pos] = ret
                return
            if outcome.kind == "error":
                err = str(outcome.value).strip().splitlines()[-1:] or ["error"]
                status, msg, never = "failed", f"the job raised before or after its task: {err[0]}", ""
            else:
                status, msg = "killed", killed_message(outcome.state, jid)
                never = f"never started ({state_text(outcome.state, jid)})"
            status = record_outcome(sweep_dir, idx, status, msg, missing_error=never, slurm_job_id=jid,
                                       slurm_state=outcome.state)
            msg = never if status == "missing" else msg
            log.warning("job #%d (%s): %s: %s", idx, jid, status, msg)
            returns[pos] = JobReturn(overrides=list(job_overrides[pos]), status=JobStatus.COMPLETED,
                                     _return_value={"status": status, "error": msg})

        wp = self.wait_params
        wait_for_jobs(jobs, states=slurm_states, poll_s=wp["poll_s"], grace_polls=int(wp["grace_polls"]),
                      unreachable_s=wp["unreachable_s"], report=report)
        return returns


def _kept_jobs(sweep_dir: Path) -> dict[int, dict]:
    """job number -> status of the jobs of ``sweep_dir`` whose result a resume keeps."""
    out = {}
    for d in job_dirs(sweep_dir):
        st = read_status(d)
        if st and st.get("status") in KEEP and isinstance(st.get("job_num"), int):
            out[st["job_num"]] = st
    return out
