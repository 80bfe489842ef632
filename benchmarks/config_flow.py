"""Follow the configuration through the evaluator: from the case experiment's entry
(``eval.experiments.cases.cases_experiment.run``), which project modules' functions
receive a part of it, and how often a call climbs back up a floor.

    python benchmarks/config_flow.py [FAUST_ROOT] [--methods SShaDe ARAP]

One FAUST case (the first) is run in this process under ``sys.setprofile``; a call
"carries the configuration" when one of its arguments is one of the checked config's
typed objects (a frozen dataclass of ``eval.run.spec`` or a per-kind ``*Options``).
A "climb" is such a call from a module on a lower floor into one on a higher floor
(floors: tests/test_layering.py's ``FLOORS`` and ``EVAL_FLOORS``). Prints the modules
visited with their call counts, the climbs, and the totals. Method workers run in
this process (``jobs=1``), so the methods' own modules count too when they get a
config object (they get plain values)."""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the repository, as the other benchmarks

from tests.test_layering import EVAL_FLOORS, FLOORS  # noqa: E402  (the floors, written once)


def floor(module: str) -> tuple[int, int]:
    """(package floor, floor inside eval/) of a dotted module name."""
    pkg = module.split(".")[0]
    # the longest matching prefix decides (eval.run before eval)
    best = max((p for p in EVAL_FLOORS if module == p or module.startswith(p + ".")), key=len, default="eval")
    inner = EVAL_FLOORS[best] if pkg == "eval" else 0
    return FLOORS.get(pkg, -1), inner


def is_config(value) -> bool:
    """``value`` is one of the checked config's typed objects."""
    t = type(value)
    typed = t.__module__ == "eval.run.spec" or (t.__module__.startswith("eval.") and t.__name__.endswith("Options"))
    return dataclasses.is_dataclass(value) and not isinstance(value, type) and typed


def trace(entry, spec) -> tuple[Counter, Counter]:
    """Run ``entry(spec)`` under a profiler; (calls per module carrying the config,
    climbs as (from, to) pairs)."""
    visits, climbs = Counter(), Counter()
    roots = tuple(str(ROOT / p) for p in FLOORS)

    def prof(frame, event, arg):
        if event != "call" or not frame.f_code.co_filename.startswith(roots):
            return
        code = frame.f_code
        args = [frame.f_locals.get(n) for n in code.co_varnames[:code.co_argcount + code.co_kwonlyargcount]]
        if not any(is_config(a) for a in args):
            return
        mod = frame.f_globals.get("__name__", "?")
        visits[mod] += 1
        caller = frame.f_back.f_globals.get("__name__", "?") if frame.f_back else "?"
        if caller.split(".")[0] in FLOORS and floor(mod) > floor(caller):
            climbs[(caller, mod)] += 1

    sys.setprofile(prof)
    try:
        entry(spec)
    finally:
        sys.setprofile(None)
    return visits, climbs


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("faust_root", nargs="?", default=str(ROOT.parent / "shared" / "data" / "faust_reg"))
    p.add_argument("--methods", nargs="+", default=["SShaDe", "ARAP"])
    a = p.parse_args(argv)
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR
    from eval.config_check import check_config
    from eval.experiments.cases.cases_experiment import run
    with tempfile.TemporaryDirectory() as tmp:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base=None):
            cfg = compose(config_name="config", overrides=[
                "dataset=faust", f"dataset.root={a.faust_root}", "dataset.limit=1", f"methods=[{','.join(a.methods)}]",
                "jobs=1", "reference.cases=none", "report.enabled=false", f"out_dir={tmp}/out"])
        spec = check_config(cfg)
        visits, climbs = trace(run, spec)
    print(f"from eval.experiments.cases.cases_experiment.run, methods {a.methods}, one FAUST case:")
    for mod, n in sorted(visits.items(), key=lambda kv: (floor(kv[0]), kv[0])):
        print(f"  {mod:50s} floor {floor(mod)}  {n} call(s) carrying the config")
    for (src, dst), n in sorted(climbs.items()):
        print(f"  climb: {src} -> {dst} ({n})")
    print(f"modules visited: {len(visits)}; climbs back up: {sum(climbs.values())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
