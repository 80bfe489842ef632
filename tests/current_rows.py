"""Committed rows made current for a test: a copy of a ``results/`` folder whose records
are re-signed with this checkout's code identity, as if this checkout had made them (the
numbers kept) on this machine, and whose tables are rebuilt without pending marks. The tests
that hold what an edit stales need rows that are current before the edit, whatever the
committed rows' state (current, or pending after a change to the shared code) and whatever
machine made them."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from eval.run.result_store import fields_digest, record_digest
from eval.run.runinfo import machine_info
from eval.run.stale_rows import current_code, record_paths, run_folders


def resign_current(top, root: str | None = None, machine: dict | None = None) -> int:
    """Re-sign every record of the run folders under ``top`` with the code identity of the
    checkout ``root`` (default: this one): their ``code`` sources, modules, constants and
    reference identity (:func:`eval.run.stale_rows.current_code`), their ``machine`` set to
    ``machine`` (None: left as it is), then their key and digest. Returns the records
    re-signed."""
    n = 0
    for folder in run_folders(Path(top)):
        for _, p in record_paths(folder):
            rec = json.loads(p.read_text())
            fields = rec["key_fields"]
            fields["code"] = current_code(fields, root)
            if machine is not None:
                rec["machine"] = machine
            rec["key"] = fields_digest(fields)
            rec["digest"] = record_digest(rec)
            p.write_text(json.dumps(rec, indent=1) + "\n")
            n += 1
    return n


def current_copy(src, dst, root: str | None = None, machine: dict | None = None) -> Path:
    """``src`` (a run folder of ``results/``) copied to ``dst``, its records re-signed as
    current at ``root`` and made on ``machine`` (None: this one, :func:`machine_info`;
    :func:`resign_current`) and its tables rebuilt (pending marks gone). Returns ``dst``."""
    from eval.tables import retabulate
    shutil.copytree(src, dst)
    resign_current(dst, root, machine_info() if machine is None else machine)
    retabulate(dst)
    return Path(dst)
