"""A machine where the optional modules and programs are missing or broken: a child pytest run
in which open3d, polyscope, mlcroissant, body_models, anny and mkdocs raise an ImportError that is
not a ModuleNotFoundError (as open3d does without the system's libusb), torch raises an
OSError (a shared library that does not load), and PATH has no Chromium and no xvfb-run.
There the tests that need one of them skip, each with one line naming what is missing, none
errors or fails, and every package module still imports (pytest imports each for its
doctests)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from .conftest import ROOT

#: module -> the exception its import raises in the child run
BROKEN = {"open3d": "ImportError", "polyscope": "ImportError", "mlcroissant": "ImportError",
          "body_models": "ImportError", "anny": "ImportError", "torch": "OSError",
          "mkdocs": "ImportError"}
#: programs taken off PATH (eval.report.find_chromium's names, xvfb-run, node)
PROGRAMS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "xvfb-run", "node")
#: test file -> what its skip lines say (each skip line names one of these, each is named)
EXPECTED = {
    "test_arap_sr_open3d": ["open3d cannot be imported (ImportError: open3d: libdemo.so.0"],
    "test_implicit_arap": ["torch cannot be imported (OSError: torch: libdemo.so.0"],
    "test_view": ["polyscope cannot be imported (ImportError: polyscope: libdemo.so.0", "xvfb-run not found on PATH"],
    "test_report": ["chromium not found on PATH"],
    "test_defaust_croissant": ["mlcroissant cannot be imported (ImportError: mlcroissant: libdemo.so.0"],
    "test_defaust_anny": ["ANNY body model assets not found"],
    "test_defaust_anny_path": ["ANNY body model assets not found"],
    "test_gltf": ["node is not on PATH"],
    "test_site_hooks": ["mkdocs cannot be imported (ImportError: mkdocs: libdemo.so.0"],
}
MARKS = "anny or neural or view or open3d or browser or xvfb or mlcroissant or gltf or docs"
PACKAGES = ("sshade", "harness", "baselines", "defaust", "eval")  # pyproject's testpaths besides tests/

SITECUSTOMIZE = f'''import sys
class _Broken:
    errors = {{"ImportError": ImportError, "OSError": OSError}}
    names = {BROKEN!r}
    def find_spec(self, name, path=None, target=None):
        kind = self.names.get(name.split(".")[0])
        if kind:
            raise self.errors[kind](f"{{name}}: libdemo.so.0: cannot open shared object file (simulated bare machine)")
        return None
sys.meta_path.insert(0, _Broken())
'''
#: a pytest plugin (-p) of the child run: one JSON line per report that is not a pass
#: (every outcome of the test calls), the skip reason without pytest's "Skipped: "
REPORTS = '''import json, os
def _log(report):
    reason = report.longrepr[2] if report.skipped and isinstance(report.longrepr, tuple) else str(report.longrepr)
    with open(os.environ["SSHADE_TEST_REPORTS"], "a") as f:
        f.write(json.dumps({"nodeid": report.nodeid, "outcome": report.outcome,
                            "reason": reason.removeprefix("Skipped: ")}) + "\\n")
def pytest_runtest_logreport(report):
    if report.when == "call" or not report.passed:
        _log(report)
def pytest_collectreport(report):
    if not report.passed:
        _log(report)
'''


def _path_without_programs(tmp: Path) -> str:
    """PATH with every folder that holds one of :data:`PROGRAMS` replaced by a folder of
    links to its other entries."""
    out = []
    for i, d in enumerate(os.environ.get("PATH", "").split(os.pathsep)):
        if d and any((Path(d) / p).exists() for p in PROGRAMS):
            shadow = tmp / f"bin{i}"
            shadow.mkdir()
            for f in Path(d).iterdir():
                if f.name not in PROGRAMS:
                    (shadow / f.name).symlink_to(f)
            d = str(shadow)
        out.append(d)
    return os.pathsep.join(out)


def _bare_machine_env(tmp: Path) -> dict:
    site = tmp / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)  # imported at start-up, children included
    (site / "sshade_test_reports.py").write_text(REPORTS)
    pythonpath = os.pathsep.join(p for p in (str(site), str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, PYTHONPATH=pythonpath, PATH=_path_without_programs(tmp),
                SSHADE_TEST_REPORTS=str(tmp / "reports.jsonl"))


def test_without_optional_modules_and_programs_their_tests_skip_in_one_line_and_none_errors(tmp_path):
    env = _bare_machine_env(tmp_path)
    for p in PROGRAMS:
        assert subprocess.run(["sh", "-c", f"command -v {p}"], env=env, capture_output=True).returncode != 0, p
    files = [f"tests/{name}.py" for name in EXPECTED]
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "no:cacheprovider",  # no workers
                        "-p", "sshade_test_reports", f"--basetemp={tmp_path / 't'}", "-m", MARKS, *files, *PACKAGES],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    tail = r.stdout[-4000:] + r.stderr[-2000:]
    assert r.returncode == 0, tail  # no failure, no error, no collection error (every package module imported)
    summary = r.stdout.strip().splitlines()[-1]
    assert " skipped" in summary and not any(w in summary for w in ("passed", "failed", "error")), tail

    skips: dict[str, list[str]] = {name: [] for name in EXPECTED}
    for line in (tmp_path / "reports.jsonl").read_text().splitlines():
        rep = json.loads(line)
        where, reason = rep["nodeid"], rep["reason"]
        assert rep["outcome"] == "skipped", f"{where} {rep['outcome']}: it should skip\n{reason}"
        assert "\n" not in reason.strip(), f"{where}: the skip reason is not one line: {reason!r}"
        name = Path(where.split("::")[0]).stem
        assert name in skips, f"{where}: skipped, outside {files}: {reason}"
        skips[name].append(reason)
    for name, wanted in EXPECTED.items():
        assert skips[name], f"{name}: no test ran (are its tests marked with one of {MARKS!r}?)"
        for reason in skips[name]:
            assert any(w in reason for w in wanted), f"{name}: {reason!r} names none of {wanted}"
        for w in wanted:
            assert any(w in reason for reason in skips[name]), f"{name}: no skip line says {w!r}: {skips[name]}"
