"""Committed rows made current for a test: a copy of a ``results/`` folder whose records
are re-signed with this checkout's code identity, as if this checkout had made them (the
numbers kept), and whose tables are rebuilt without pending marks. The tests that hold
what an edit stales need rows that are current before the edit, whatever the committed
rows' state (current, or pending after a change to the shared code)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

from eval.run.code_identity import (
    ARTIFACTS,
    artifact_identity,
    closure_constants,
    identity_roots,
    import_closure,
    modules_digest,
)
from eval.run.result_store import fields_digest, record_digest
from eval.run.stale_rows import record_paths, references_on, run_folders


def resign_current(top, root: str | None = None) -> int:
    """Re-sign every record of the run folders under ``top`` with the code identity of the
    checkout ``root`` (default: this one): their ``code`` sources, modules, constants and
    reference identity, then their key and digest. Returns the records re-signed."""
    n = 0
    ref = artifact_identity(root)
    for folder in run_folders(Path(top)):
        for _, p in record_paths(folder):
            rec = json.loads(p.read_text())
            fields = rec["key_fields"]
            roots = identity_roots(fields.get("method"), references_on(fields))
            mods, consts = import_closure(roots, root, ARTIFACTS), closure_constants(roots, root, ARTIFACTS)
            code = fields["code"]
            code.update(sources=modules_digest(mods, root, consts), modules=list(mods), constants=list(consts))
            if "reference" in code:
                code["reference"] = ref
            rec["key"] = fields_digest(fields)
            rec["digest"] = record_digest(rec)
            p.write_text(json.dumps(rec, indent=1) + "\n")
            n += 1
    return n


def current_copy(src, dst, root: str | None = None) -> Path:
    """``src`` (a run folder of ``results/``) copied to ``dst``, its records re-signed as
    current at ``root`` (:func:`resign_current`) and its tables rebuilt (pending marks
    gone). Returns ``dst``."""
    from eval.tables import retabulate
    shutil.copytree(src, dst)
    resign_current(dst, root)
    retabulate(dst)
    return Path(dst)
