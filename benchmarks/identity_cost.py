"""What a one-line edit of a module costs in regeneration: the committed rows it stales.

For each probe file, a copy of the project's packages and of ``results/`` is made in a
temporary folder, one module-level statement (``_PROBE_EDIT = object()``, no literal:
it counts by the module's code, eval/run/code_identity.py) is appended to that file, and
the copy's committed rows are held to the copy's code (``eval.run.stale_rows.check_folders``,
as ``python -m eval.reproduce --check``). Prints, per probe, the stale rows per method and
their stored ``time_s`` in hours (what a regeneration of those rows costs on the machine
that made them; the references they need are not counted), and of them those stale only
because the code that solves their reference changed (a resumed run keeps such a row when
its reference, solved again, comes out bit for bit the one it records), as a Markdown table.

    python benchmarks/identity_cost.py                       # the default probes
    python benchmarks/identity_cost.py sshade/guard.py eval/metrics/reference.py
"""
import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from eval.run.code_identity import PACKAGES  # noqa: E402
from eval.run.stale_rows import CommitTrees, check_folders, run_folders  # noqa: E402
from harness.command import run_command  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe")
#: the edits the identity is meant to survive or to catch: the shared solver, the mesh
#: reader, the mesh checks, the guard, the dataset package, the metrics, the references
#: and one baseline's own module
PROBES = ("sshade/arap/solver.py", "sshade/mesh/io.py", "sshade/mesh/validate.py", "sshade/guard.py",
          "eval/datasets/__init__.py", "eval/metrics/reference.py", "eval/metrics/reference_scores.py",
          "eval/metrics/measures.py",
          "baselines/implicit_arap/method.py")


def probe(path: str, trees: CommitTrees) -> dict:
    """``{method: [stale rows, rows, stale hours, of them stale for the reference only]}``
    after the probe edit of ``path``."""
    with tempfile.TemporaryDirectory(prefix="sshade-probe-") as tmp:
        tree = Path(tmp)
        for d in PACKAGES:
            shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
        shutil.copytree(ROOT / "results", tree / "results", ignore=shutil.ignore_patterns("*.png", "report"))
        if path:
            with open(tree / path, "a") as fh:
                fh.write("\n_PROBE_EDIT = object()\n")
        out: dict = {}
        for ms in check_folders(run_folders(tree / "results"), trees, str(tree)).values():
            for m, v in ms.items():
                agg = out.setdefault(m, [0, 0, 0.0, 0])
                agg[0] += v["stale"] + v.get("pending", 0)
                agg[1] += v["rows"]
                agg[2] += v["stale_s"] / 3600
                agg[3] += sum(k for why, k in v["why"].items() if why.startswith("its reference solver"))
        return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/identity_cost.py", description=__doc__.split("\n\n")[0])
    p.add_argument("probes", nargs="*", default=list(PROBES), help="files to edit (relative to the repository)")
    a = p.parse_args(argv)
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True, check=False).stdout.strip()
    print(f"Rows of results/ a probe edit stales at {head} (stale / rows, stored hours)\n")
    print("| edit of | " + " | ".join(METHODS) + " | all | hours | reference only |")
    print("|---|" + "---:|" * (len(METHODS) + 3))
    with CommitTrees() as trees:
        for path in ["", *a.probes]:
            got = probe(path, trees)
            cells = [f"{got.get(m, [0, 0])[0]} / {got.get(m, [0, 0])[1]}" for m in METHODS]
            n, rows, hours, ref = (sum(v[i] for v in got.values()) for i in range(4))
            print(f"| {path or '(nothing)'} | " + " | ".join(cells) + f" | {n} / {rows} | {hours:.2f} | {ref} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_command(main, where="benchmarks/identity_cost.py"))
