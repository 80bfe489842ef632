"""One leaderboard of method x dataset over the run folders of a results tree
(``results/leaderboard.md`` and the top of ``results/index.html``, written by
``python -m eval.report --index results``, the ``report`` step of ``python -m eval.reproduce``).
Floor 5 of eval/ (the commands, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from eval.datasets import find_dataset
from eval.present.intervals import CI, bootstrap_ci, interval_text
from eval.present.measures import MEASURES, label
from eval.present.rows import methods_in
from eval.present.stops import stop_lines
from eval.run.compared import COMPARED_CSV, checked_compared
from eval.run.pending_rows import marked_pending, marked_run
from eval.run.row_check import checked_cases, read_cases
from eval.run.runinfo import read_runinfo
from eval.run.stale_rows import CommitTrees, check_folders, run_folders
from eval.tables import common_case_values, compare
from sshade.pipeline import SShaDe

__all__ = ["LEADERBOARD", "HEADING", "Board", "collect", "leaderboard_markdown", "leaderboard_rows", "listed_words",
           "mark_word", "stale_words", "LABELS", "RANK_COLUMN", "run_board_markdown"]

LEADERBOARD = "leaderboard.md"  #: the file written beside ``index.html``
#: Folder name -> the dataset's name on the board (other folders: their own name).
LABELS = {"faust": "FAUST", "defaust": "DeFAUST", "defaust_paper": "DeFAUST (paper protocol)",
          "defaust_faust": "DeFAUST of FAUST bodies", "defaust_faust_paper": "DeFAUST of FAUST bodies (paper protocol)",
          "shapes": "Stanford shapes", "animation": "Animated DeFAUST", "tosca": "TOSCA"}
#: The paired test that separates ranks, and its level. In order of GT mean, a method shares
#: the rank of the group above unless this test over the same cases says it is farther from
#: the truth than that group's first method; then it starts a group whose rank is its place.
RANK_TEST = ("two-sided Wilcoxon signed-rank test over the same cases", 0.05)
#: How a rank is read, in words.
RANK_WORDS = (f"in order of GT mean, a method shares the rank of the group above unless a {RANK_TEST[0]} "
              f"at p < {RANK_TEST[1]} says it is farther from the truth than that group's first method")
#: The column that ranks, and its words.
RANK_COLUMN = ("gt_vertex_mean_pct", f"{label('gt_vertex_mean_pct')}: mean distance to the true pose, % of the "
                                     "bounding-box diagonal")
REFERENCE = SShaDe.name  #: times are relative to this method in the same run
#: The measures a board shows after its rank column, in order.
BOARD_MEASURES = ("volume_err_pct", "edge_err_pct", "angle_err_deg")


@dataclass
class Board:
    """One dataset's entries. ``rows``: per method ``method``, ``gt`` (or None), the
    :data:`BOARD_MEASURES` (by key), ``time_rel`` (x SShaDe, or None), ``rank`` (or None),
    ``stopped``."""
    folder: str
    label: str
    commit: str
    n_cases: int
    ranked: bool
    why_not: str = ""
    rank_column: str = RANK_COLUMN[0]
    time_words: str = ""
    rows: list = field(default_factory=list)
    stale: dict = field(default_factory=dict)  # method -> (stale rows, stored rows) at this checkout
    data: tuple = ("", "")  # (heading tag, sentence) on data other than its canonical build (_data_mark)


def _num(v):
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _paired_ranks(per_case: dict, means: dict) -> dict:
    """``{method: rank}`` by :data:`RANK_TEST`: in order of ``means`` (lowest first), each
    method joins the rank of the group above unless its per-case values (``per_case[m]``:
    the same cases in the same order for every method) differ from those of the group's
    first method by the test at its level (then its rank is its place, 1-based).

    >>> a, b = [1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6], [2.0, 2.2, 2.1, 2.4, 2.3, 2.5, 2.6]
    >>> _paired_ranks({"A": a, "B": b, "C": b[::-1]}, {"A": 1.3, "B": 2.3, "C": 2.3})
    {'A': 1, 'B': 2, 'C': 2}
    """
    from scipy.stats import wilcoxon
    order = sorted(per_case, key=lambda m: (means[m], m))
    out, lead = {}, None
    for place, m in enumerate(order, start=1):
        if lead is not None:
            d = [x - y for x, y in zip(per_case[m], per_case[lead])]
            try:
                p = float(wilcoxon(d, alternative="two-sided").pvalue) if any(d) else 1.0
            except ValueError:  # too few non-zero differences
                p = 1.0
            if not p < RANK_TEST[1]:
                out[m] = out[lead]
                continue
        lead, out[m] = m, place
    return out


def _case_ranks(df, comp, gt: list, methods: list) -> tuple[list, list]:
    """The ranks of ``methods`` (the main table's rows, GT means ``gt``) by
    :func:`_paired_ranks` over the common cases' successful rows of ``df``, and each
    one's :func:`bootstrap_ci` over those cases (None lists where a method lacks one)."""
    values = common_case_values(df, comp, RANK_COLUMN[0])
    per = {}
    for m in methods:
        g = values.get(m)
        if g is None or len(g) != len(comp.cases or []) or g.isna().any():
            return [None] * len(methods), [None] * len(methods)
        per[m] = g.tolist()
    means = {m: (v if v is not None else float("inf")) for m, v in zip(methods, gt)}
    r = _paired_ranks(per, means)
    return [r.get(m) for m in methods], [bootstrap_ci(per[m]) for m in methods]


def _config(info: dict) -> dict:
    return info.get("config") if isinstance(info.get("config"), dict) else {}


def _paper(info: dict) -> bool:
    """Whether the run's methods ran under the paper protocol (``arap.protocol``)."""
    return (_config(info).get("arap") or {}).get("protocol") == "paper"


def _label(d: Path, info: dict) -> str:
    """The board's column heading: :data:`LABELS`, else the run's dataset name, with
    "(paper protocol)" when its methods ran under it (never a bare folder name)."""
    if d.name in LABELS:
        return LABELS[d.name]
    name = str((_config(info).get("dataset") or {}).get("name") or d.name)
    return LABELS.get(name, name) + (" (paper protocol)" if _paper(info) else "") + f" ({d.name}/)"


def _rank_words(info: dict, n_cases: int, column: str) -> str:
    """What a board ranks by: ``column``, at the paper protocol's stopping rule when its
    methods ran under it (the ranks are then of that rule, converged or not), saying so
    when they rest on one case."""
    words = column
    if _paper(info):
        words += (" at the paper protocol's stopping rule (its iteration cap or tolerance, §4.1; the Stopped column "
                  "says how many runs converged): the ranks are of that rule, not of converged methods")
    if n_cases == 1:
        words += "; on one case only: the ranks are of that case"
    return words


def _cases_board(d: Path, info: dict, *, compared: bool = False) -> Board | None:
    """The board of a ``cases`` run folder (its ``cases.csv``; with ``compared`` also the
    rows its ``compare_with`` read, ``compared.csv``, already checked like with like:
    ranked beside this run's, their times left out as another run's), or None without one.
    SShaDeError naming the file when a row disagrees with its record
    (:func:`eval.run.row_check.checked_cases`, :func:`eval.run.compared.checked_compared`)."""
    import pandas as pd
    if not os.path.lexists(d / "cases.csv"):
        return None
    df = checked_cases(d)  # ranked only when every row is its record's (SShaDeError otherwise)
    other: set = set()
    if compared:
        extra = checked_compared(d)
        if extra is not None and "method" in extra.columns:
            other = set(map(str, extra["method"]))
            df = pd.concat([df, extra], ignore_index=True)
    if "method" not in df.columns or not len(df):
        return None
    comp = compare(df)
    main = comp.main
    stops = {ln.split(":", 1)[0]: ln.split(":", 1)[1].strip() for ln in stop_lines(df, short=True)}
    gt = [_num(v) for v in main.get(RANK_COLUMN[0], [None] * len(main))]
    has_gt = any(v is not None for v in gt)
    ranked = has_gt and comp.same_cases
    why = ("" if ranked else "no ground truth: not ranked" if not has_gt
           else "methods averaged different cases: not ranked")
    ref = main.loc[main["method"] == REFERENCE, "time_s"] if "time_s" in main.columns and REFERENCE not in other else []
    ref_t = _num(ref.iloc[0]) if len(ref) else None
    ranks, cis = (_case_ranks(df, comp, gt, [str(m) for m in main["method"]]) if ranked
                  else ([None] * len(main), [None] * len(main)))
    n = int(main["n_cases"].max()) if len(main) else 0
    b = Board(folder=d.name, label=_label(d, info), commit=_commit(info), n_cases=n, ranked=ranked, why_not=why,
              rank_column=_rank_words(info, n, RANK_COLUMN[0]), data=_data_mark(info))
    for i, (_, r) in enumerate(main.iterrows()):
        t = None if str(r["method"]) in other else _num(r.get("time_s"))  # never a time across runs
        b.rows.append({"method": str(r["method"]), "gt": gt[i], **{k: _num(r.get(k)) for k in BOARD_MEASURES},
                       "time_rel": t / ref_t if t is not None and ref_t else None, "rank": ranks[i],
                       "ci": cis[i], "stopped": stops.get(str(r["method"]), "")})
    return b


def _animation_board(d: Path, info: dict) -> Board | None:
    """The board of an ``animation`` run folder (its ``table.csv``: one row per method)."""
    try:
        t = read_cases(d / "table.csv")
    except (OSError, ValueError):
        return None
    if not {"method", "gt_mean_pct"} <= set(t.columns):
        return None
    gt = [_num(v) for v in t["gt_mean_pct"]]
    ref = t.loc[t["method"] == REFERENCE, "frame_median_s"] if "frame_median_s" in t.columns else []
    ref_t = _num(ref.iloc[0]) if len(ref) else None
    n = int(t["n_cases"].max()) if "n_cases" in t.columns else 0
    # one row per method, no per-case rows: no paired test can separate them
    b = Board(folder=d.name, label=_label(d, info), commit=_commit(info), n_cases=n, ranked=False,
              why_not=f"not ranked: its table has no per-case rows for the paired test ({RANK_TEST[0]})",
              rank_column="gt_mean_pct (the ground-truth error over every frame)",
              time_words=" (median seconds per frame)", data=_data_mark(info))
    for i, (_, r) in enumerate(t.iterrows()):
        tm = _num(r.get("frame_median_s"))
        b.rows.append({"method": str(r["method"]), "gt": gt[i], **dict.fromkeys(BOARD_MEASURES),
                       "time_rel": tm / ref_t if tm is not None and ref_t else None, "rank": None,
                       "stopped": str(r.get("how", "")) + (f"; {int(r['n_converged'])} frames converged"
                                                           if _num(r.get("n_converged")) is not None else "")})
    return b


def _stale(d: Path, trees: CommitTrees) -> dict:
    """``{method: (stale, rows, commits, modules, marked)}`` of the stored rows of run
    folder ``d`` (and of the folders below it) whose code identity differs from this
    checkout's, with the commits that made them, the modules changed since and how many of
    them its tables list as pending (:func:`eval.run.stale_rows.check_folders`); methods
    without such a row left out."""
    out: dict = {}
    for ms in check_folders(run_folders(d), trees, marked=marked_pending).values():
        for m, v in ms.items():
            k, n, c, ch, j = out.get(m, (0, 0, set(), set(), 0))
            out[m] = (k + v["stale"], n + v["rows"], c | v["commits"], ch | v["changed"], j + v["marked"])
    return {m: knc for m, knc in out.items() if knc[0]}


def stale_words(stale: tuple | None) -> str:
    """A cell's mark for a method with rows not made by this checkout's code, with the
    commits that made them and the modules changed since (at most three named): ``pending``
    when its tables list every one of them (``stale[4]``, the rows listed, equals
    ``stale[0]``), ``stale`` otherwise, with how many are listed:
    ``" [pending: 8 of 40 rows, made at 3e79476; sshade.guard changed]"``,
    ``" [stale: 8 of 40 rows (3 listed pending), made at 3e79476]"``; ``""`` for none."""
    if not stale or not stale[0]:
        return ""
    changed = sorted(stale[3]) if len(stale) > 3 else []
    more = f" and {len(changed) - 3} more" if len(changed) > 3 else ""
    what = f"; {', '.join(changed[:3])}{more} changed" if changed else ""
    listed = stale[4] if len(stale) > 4 else 0
    return f" [{mark_word(stale[0], listed)}: {stale[0]} of {stale[1]} rows{listed_words(stale[0], listed)}, " \
           f"made at {', '.join(sorted(stale[2]))}{what}]"


def mark_word(older: int, listed: int) -> str:
    """``"pending"`` when the tables list all ``older`` rows made by other code than this
    checkout's (``listed`` of them), ``"stale"`` otherwise."""
    return "pending" if listed >= older else "stale"


def listed_words(older: int, listed: int) -> str:
    """How many of ``older`` stale rows are listed pending, ``""`` when none or all are."""
    return f" ({listed} listed pending)" if 0 < listed < older else ""


def _marks_legend(marks: list[tuple]) -> str:
    """The leaderboard's sentence on the cells marked by :func:`stale_words` (``marks``:
    their tuples), naming only the marks it shows; ``""`` for none."""
    words = {mark_word(m[0], m[4] if len(m) > 4 else 0) for m in marks if m and m[0]}
    if not words:
        return ""
    what = " or ".join(f"[{w}: k of n rows, made at C]" for w in sorted(words))
    return (f" A cell marked {what} holds rows made by the code of commit C, which changed since "
            "(`python -m eval.reproduce --check` names the modules): not this checkout's numbers"
            + ("; pending: its tables list them, to be made again (`python -m eval.reproduce --budget`)"
               if "pending" in words else "")
            + ("; stale: no table lists them yet (`python -m eval.reproduce --retabulate` marks them)"
               if "stale" in words else "") + ".")


def _data_mark(info: dict) -> tuple[str, str]:
    """``(tag, sentence)`` for a board whose run read data other than its dataset's
    canonical build (``run.json``'s ``dataset_build``, :func:`eval.datasets.defaust_dataset.build_provenance`),
    or whose run, of a dataset that has a canonical build, recorded no such check, or that
    left rows pending from a run on other case data (``rows_on_other_data``); ``("", "")`` otherwise."""
    build = info.get("dataset_build")
    if isinstance(build, dict):
        other = build.get("rows_on_other_data")
        if build.get("canonical") is True and isinstance(other, int) and other > 0:
            return f" ({other} rows on another build)", str(build.get("mark") or "")
        if build.get("canonical") is True:
            return "", ""
        mark = build.get("mark")
        return " (not the canonical build)", mark if isinstance(mark, str) and mark else "not on the canonical build"
    name = (_config(info).get("dataset") or {}).get("name")
    d = find_dataset(name) if isinstance(name, str) else None
    if d is None or d.provenance is None:
        return "", ""
    return (" (build unchecked)", "its run recorded no check of its data against the canonical build (a run made "
            "before runs did): its rows may stand on other meshes than the canonical build's")


def _data_legend(tags: set) -> str:
    """The leaderboard's sentence on the data tags its columns carry (:func:`_data_mark`)."""
    said = [w for k, w in (("(not the canonical build)", "headed (not the canonical build) holds rows made on "
                            "other data than the dataset's canonical build (`python -m defaust verify`)"),
                           ("(build unchecked)", "headed (build unchecked) rows whose run did not check"),
                           ("rows on another build)", "headed (k rows on another build) a run on the canonical "
                            "build that left k rows of an earlier build pending")) if any(k in t for t in tags)]
    return f" A column {'; one '.join(said)}: comparable with rows of the same build only." if said else ""


def _commit(info: dict) -> str:
    c = (info.get("git") or {}).get("commit") if isinstance(info.get("git"), dict) else None
    return c[:12] if isinstance(c, str) else ""


def collect(root) -> tuple[list[Board], list[str]]:
    """The boards of the run folders directly below ``root`` (``cases`` and ``animation``
    runs), in the order of :data:`LABELS` then by name, and the lines of the runs listed
    apart (TOSCA: its classes' ground-truth error, SShaDe's transfer only)."""
    root = Path(root)
    order = list(LABELS)
    boards, apart = [], []
    with CommitTrees() as trees:
        for d in sorted((p.parent for p in root.glob("*/run.json")),
                        key=lambda p: (order.index(p.name) if p.name in order else len(order), p.name)):
            info = read_runinfo(d)
            kind = str(((info.get("config") or {}).get("experiment") or {}).get("kind", "cases"))
            b = (_cases_board(d, info) if kind == "cases" else _animation_board(d, info) if kind == "animation"
                 else None)
            if b is not None and b.rows:
                b.stale = _stale(d, trees)
                made = marked_run(d) if kind == "animation" else None  # a folder run whole, marked by --retabulate
                if made is not None:  # one row per method in its table
                    b.stale = {r["method"]: (1, 1, {made}, set(), 1) for r in b.rows}
                boards.append(b)
            elif kind == "tosca":
                apart += _tosca_line(d)
    return boards, apart


def _tosca_line(d: Path) -> list[str]:
    try:
        t = read_cases(d / "table.csv")
        r = t[t["class"].astype(str).str.startswith("all")].iloc[0]
    except (OSError, ValueError, KeyError, IndexError):
        return []
    return [f"{LABELS['tosca']} ([{d.name}/]({d.name}/index.html)): SShaDe's isometric transfer only (no other "
            f"method does this task here), GT mean {float(r['gt_vertex_mean_pct']):.4f} % over "
            f"{int(r['n_cases'])} cases"]


def _f(v, dec: int, suffix: str = "") -> str:
    return "--" if v is None else f"{v:.{dec}f}{suffix}"


def _ci(ci) -> str:
    """The ranked measure's interval as the tables write one (:func:`interval_text`, its
    decimals), ``--`` without one."""
    return interval_text(ci, f".{MEASURES[RANK_COLUMN[0]].decimals}f") or "--"


def leaderboard_rows(boards: list[Board]) -> tuple[list[str], list[list[str]]]:
    """The method x dataset matrix: header and one row per method (each cell ``GT (rank)``,
    or ``Vol/EL/FA`` where the dataset has no ground truth, ``--`` where it did not run)."""
    import pandas as pd
    methods = methods_in(pd.DataFrame({"method": [r["method"] for b in boards for r in b.rows]}))
    head = ["Method", *[b.label + b.data[0] for b in boards]]
    rows = []
    for m in methods:
        cells = [m]
        for b in boards:
            r = next((x for x in b.rows if x["method"] == m), None)
            if r is None:
                cells.append("--")
            elif r["gt"] is not None:
                cells.append(_f(r["gt"], 2) + (f" ({r['rank']})" if r["rank"] is not None else "")
                             + stale_words(b.stale.get(m)))
            else:
                cells.append(" / ".join(_f(r[k], 2) for k in BOARD_MEASURES) + stale_words(b.stale.get(m)))
        rows.append(cells)
    return head, rows


def _board_section(b: Board, link: str) -> list[str]:
    """One board's heading, words and ranked table (Markdown lines)."""
    out = ["", f"## {b.label}", "",
           f"{link}, commit {b.commit or 'unknown'}; mean over {b.n_cases} case(s) every method ran on; "
           + (f"ranked by {b.rank_column}" if b.ranked else b.why_not)
           + f"; Time relative to {REFERENCE} in the same run{b.time_words}."
           + (f" Data: {b.data[1]}." if b.data[1] else ""), "",
           f"| Rank | Method | {label(RANK_COLUMN[0])} | {CI[0]:.0%} CI | {' | '.join(map(label, BOARD_MEASURES))} "
           f"| Time (x {REFERENCE}) | Stopped |",
           "|---:|---|---:|---:|---:|---:|---:|---:|---|"]
    for r in sorted(b.rows, key=lambda x: (x["rank"] is None, x["rank"] or 0,
                                           x["gt"] if x["gt"] is not None else math.inf)):
        out.append(f"| {r['rank'] if r['rank'] is not None else '--'} | {r['method']}"
                   f"{stale_words(b.stale.get(r['method']))} | {_f(r['gt'], MEASURES[RANK_COLUMN[0]].decimals)} | "
                   f"{_ci(r.get('ci'))} | "
                   + "".join(f"{_f(r[k], MEASURES[k].decimals)} | " for k in BOARD_MEASURES)
                   + f"{_f(r['time_rel'], 2, 'x')} | "
                   f"{r['stopped'].replace('|', '/')} |")
    return out


def run_board_markdown(run_dir) -> str | None:
    """The board of one run folder that read earlier runs' rows (``compare_with``): its
    methods ranked beside theirs, as the leaderboard ranks (``leaderboard.md`` of the run,
    written by :func:`eval.report.write_report`); None without compared rows."""
    d = Path(run_dir)
    if not (d / COMPARED_CSV).is_file():
        return None
    info = read_runinfo(d)
    b = _cases_board(d, info, compared=True)
    if b is None or not b.rows:
        return None
    return "\n".join([HEADING, "",
                      f"Written by `python -m eval.report {d.name}` at the end of the run: this run's methods ranked "
                      "beside the rows its compare_with read (their records checked like with like: "
                      "compared.csv); their times are another run's and are left out.", *_board_section(b, "this run")]
                     ) + "\n"


#: The first line of a leaderboard this module wrote (a file that does not start so is not replaced).
HEADING = "# Leaderboard"


def leaderboard_markdown(root) -> str:
    """``leaderboard.md``'s text for the run folders below ``root`` (module docstring)."""
    boards, apart = collect(root)
    head, rows = leaderboard_rows(boards)
    out = [HEADING, "",
           f"Written by `python -m eval.report --index {Path(root).name}` (the `report` step of "
           "`python -m eval.reproduce`) from the run folders below; each cell comes from the run linked under it.",
           "",
           f"**The ranking column is {RANK_COLUMN[1]}**, the rank in parentheses (1 = nearest; {RANK_WORDS}); "
           "no other column ranks: a method best on volume may be far from the true pose. Per dataset, the GT "
           f"mean's {CI[0]:.0%} interval is a percentile bootstrap over its cases ({CI[1]} resamples, seed {CI[2]}). "
           f"Where the data has no ground truth the cell shows {' / '.join(label(k) for k in BOARD_MEASURES)} "
           "errors and nobody is ranked."
           + _marks_legend([v for b in boards for v in b.stale.values()])
           + _data_legend({b.data[0] for b in boards}), "",
           "| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    for b in boards:
        out += _board_section(b, f"[{b.folder}/]({b.folder}/index.html)")
    if apart:
        out += ["", "## Listed apart", ""] + [f"- {x}" for x in apart]
    return "\n".join(out) + "\n"
