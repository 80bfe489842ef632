"""Implicit-ARAP (baselines/implicit_arap/) where PyTorch cannot be imported: building it,
or asking the evaluator for it, fails in one line saying how to install PyTorch, whether
PyTorch is missing or installed with a library that does not load. These run whether or not
PyTorch is installed: each child process makes ``import torch`` fail."""
from __future__ import annotations

import subprocess
import sys

from .conftest import ROOT, subprocess_env

NO_TORCH = "Implicit-ARAP needs PyTorch: pip install -e .[neural]"
BLOCK_TORCH = "import sys; sys.modules['torch'] = None; "  # `import torch` raises ModuleNotFoundError
BROKEN_TORCH = """import sys
class _Broken:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "torch":
            raise OSError("libtorch_cpu.so: cannot open shared object file: No such file or directory")
sys.meta_path.insert(0, _Broken())
"""  # `import torch` raises OSError, as an installed PyTorch whose library does not load
BUILD = ("import baselines; from harness.method_registry import build_builtin\n"
         "try:\n    build_builtin('Implicit-ARAP')\nexcept Exception as e:\n"
         "    print(type(e).__name__); print(e)\n")


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env=subprocess_env())


def test_without_torch_the_build_fails_in_one_line():
    out = _run(BLOCK_TORCH + BUILD)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["SShaDeError", NO_TORCH]


def test_with_a_torch_that_does_not_load_the_build_fails_in_one_line_naming_the_error():
    out = _run(BROKEN_TORCH + BUILD)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["SShaDeError", f"{NO_TORCH} (import torch failed: OSError: "
                                       "libtorch_cpu.so: cannot open shared object file: No such file or directory)"]


def test_without_torch_the_evaluator_exits_2_before_any_work(tmp_path):
    out = _run(BLOCK_TORCH + "import runpy; sys.argv = ['eval', 'methods=[Implicit-ARAP]', "
               f"'out_dir={tmp_path / 'run'}']; runpy.run_module('eval', run_name='__main__')")
    assert out.returncode == 2, out.stdout + out.stderr
    assert NO_TORCH in out.stdout + out.stderr
    assert len([ln for ln in (out.stdout + out.stderr).splitlines() if "PyTorch" in ln]) == 1
    assert not (tmp_path / "run" / "cases.csv").exists()
