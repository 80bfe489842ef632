"""The browser report of an evaluator run: ``index.html`` in the run folder, opened from
``file://`` (no server, no network: every script is inline or a file next to it).
Floor 5 of eval/ (the commands, tests/test_layering.py); notes: docs/implementation.md.

Command line (:func:`main`)::

    python -m eval.report RUN_DIR [RUN_DIR ...]     # (re)write RUN_DIR/index.html
    python -m eval.report --index results           # results/index.html: a link per folder
    python -m eval.report --screenshot OUT.png RUN_DIR   # also a PNG of the page (chromium)

It writes only into an earlier evaluator output (:func:`eval.run.outdir.check_earlier_output`)
and into ``results/`` only under ``python -m eval.reproduce``, which runs ``--index``."""
from __future__ import annotations

import html
import json
import logging
import math
import os
import shutil
import subprocess
from pathlib import Path

from eval.experiments import find_experiment
from eval.leaderboard import (
    HEADING,
    LEADERBOARD,
    RANK_COLUMN,
    RANK_WORDS,
    collect,
    leaderboard_markdown,
    leaderboard_rows,
    listed_words,
    mark_word,
    run_board_markdown,
)
from eval.present.breakdown import BREAKDOWN_METRICS
from eval.present.intervals import CI, interval_text
from eval.present.measures import MEASURES, label
from eval.present.meshview import VIEW_DIR, read_outputs, read_view
from eval.present.report_scope import link_target, not_current, run_cases
from eval.present.table_markup import time_marks, time_notes
from eval.run.outdir import (
    REPRODUCE_ENV,
    OutputDirError,
    check_earlier_output,
    read_marker,
    record_output_files,
    refuse_results,
    results_dir,
)
from eval.run.pending_rows import marked_pending, marked_run
from eval.run.row_check import checked_cases, read_cases
from eval.run.runinfo import read_runinfo
from eval.run.stale_rows import CommitTrees, check_folders
from eval.run.stale_runs import whole_run_folders, whole_run_state
from eval.tables import (
    ALL_CASES_HEADING,
    EXTRA_COLUMNS,
    TABLE_COLUMNS,
    all_note,
    compare,
    failure_lines,
    main_note,
    stop_lines,
)
from harness.command import run_command
from sshade.command_errors import ArgumentParser
from sshade.files import atomic_write
from sshade.json_file import read_bounded, read_prefix

__all__ = ["PAGE", "GENERATOR", "CHROMIUM_FLAGS", "render_page", "write_report", "safe_report", "write_index",
           "find_chromium", "chromium", "screenshot", "main"]

log = logging.getLogger("eval")

PAGE = "index.html"  #: the report's file name in a run folder
GENERATOR = "sshade eval.report"  #: the generator meta tag: a page with another one is never replaced
MAX_SHOWN = 16 * 2**20  #: the largest text file of a run (table.md, breakdown.md) shown in its page (bytes)
_ASSETS = Path(__file__).resolve().parent / "report_assets"
_CSS = """body{font:14px/1.45 system-ui,sans-serif;margin:1.5em auto;max-width:1250px;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:.5em 0 1em}th,td{border:1px solid #ccc;padding:.2em .5em;text-align:left}
th{background:#f3f3f3;cursor:pointer;user-select:none}td[data-v]{text-align:right}
th[data-dir=asc]::after{content:" \\25B2"}th[data-dir=desc]::after{content:" \\25BC"}
#js-errors{background:#fee;border:1px solid #c00;padding:.5em;color:#900}pre{background:#f7f7f7;padding:.6em;
overflow:auto;max-height:30em}img{max-width:100%;border:1px solid #ddd}.view canvas{width:100%;display:block;
border:1px solid #ccc;cursor:grab}.view-labels{text-align:center;font-size:13px}
.view-colour{font-size:13px;margin:.3em 0}.view-colour button{margin-right:.4em}
.view-ramp{display:inline-block;width:120px;height:10px;vertical-align:middle;border:1px solid #999}
.note{color:#555}nav a{margin-right:1em}"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _cell(v, dec: int | None = None) -> str:
    """``<td>`` of one value: numbers with ``dec`` decimals (else 4 significant digits)
    and their full value in ``data-v`` (the sort key); missing values ``--``."""
    if v is None or isinstance(v, float) and not math.isfinite(v):
        return '<td data-v="">--</td>'
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"<td>{_e(v)}</td>"
    text = f"{v:.{dec}f}" if dec is not None else (str(v) if isinstance(v, int) else f"{v:.4g}")
    return f'<td data-v="{v!r}">{text}</td>'


def _table(head: list[str], rows: list[list[str]], table_id: str = "") -> str:
    """A sortable table: ``head`` texts, ``rows`` of ready ``<td>`` cells."""
    tid = f' id="{_e(table_id)}"' if table_id else ""
    ths = "".join(f"<th>{_e(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(r) + "</tr>" for r in rows)
    return f'<table class="sortable"{tid}><thead><tr>{ths}</tr></thead><tbody>{body}</tbody></table>'


def _num(v):
    try:
        f = float(v)
    except (TypeError, ValueError):
        return v
    return int(f) if f.is_integer() and abs(f) < 2 ** 53 else f


def _summary_table(summary, table_id: str) -> str:
    """The main columns (:data:`eval.tables.TABLE_COLUMNS` and ``EXTRA_COLUMNS``) of a
    per-method summary (:func:`eval.tables.summarize` layout)."""
    cols = [(c, h, d) for c, h, _, d, _ in TABLE_COLUMNS if c in summary.columns]
    cols += [(c, h, d) for c, h, d in EXTRA_COLUMNS if c in summary.columns and not MEASURES[c].fraction]
    head = ["Method", label("n_cases"), label("n_failed"), *[h for _, h, _ in cols]]
    rows, marks = [], time_marks(summary)
    for i, (_, r) in enumerate(summary.iterrows()):
        cells = [f"<td>{_e(r['method'])}</td>", _cell(int(r["n_cases"])), _cell(int(r.get("n_failed", 0) or 0))]
        for c, _, d in cols:
            cell = _cell(_num(r[c]), d)
            if c == "time_s" and i in marks and 'data-v=""' not in cell:  # a time not measured in this run
                cell = cell.replace("</td>", f" {marks[i]}</td>")
            cells.append(cell)
        rows.append(cells)
    return _table(head, rows, table_id) + "".join(f'<p class="note">{_e(n)}</p>' for n in time_notes(summary))


def _csv_table(path: Path, table_id: str = "") -> str:
    """Every column of a CSV file as a sortable table (other experiments' ``table.csv``)."""
    df = read_cases(path)
    rows = [[_cell(_num(v)) if not isinstance(v, str) else f"<td>{_e(v)}</td>" for v in r]
            for r in df.itertuples(index=False)]
    return _table([str(c) for c in df.columns], rows, table_id)


def _text(path: Path) -> str:
    """A text file of the run shown in the page (at most :data:`MAX_SHOWN` bytes, a regular
    file: :func:`sshade.json_file.read_bounded`; OSError otherwise)."""
    return read_bounded(path, MAX_SHOWN).decode("utf-8", errors="replace")


def _items(lines: list[str]) -> str:
    return "<ul>" + "".join(f"<li>{_e(s)}</li>" for s in lines) + "</ul>" if lines else ""


def _main_section(run_dir: Path, kind: str) -> str:
    """The main table(s), stopping record and failures (``cases`` experiment), else
    ``table.csv`` as it is."""
    out = ['<h2 id="main">Main table</h2>']
    cases = run_dir / "cases.csv"
    if kind == "cases" and os.path.lexists(cases):
        df = checked_cases(run_dir)  # shown only when every row is its record's
        if "method" in df.columns and len(df):
            comp = compare(df)
            note = main_note(comp)
            out += [f'<p class="note">{_e(note)}</p>' if note else "", _summary_table(comp.main, "main-table")]
            stops, fails = stop_lines(df), failure_lines(df)
            if stops:
                out += ['<h3 id="stopping">How each method stopped</h3>', _items(stops)]
            if fails:
                out += ["<h3>Failed runs (left out of every mean)</h3>", _items(fails)]
            if comp.all is not None:
                out += [f"<h3>{_e(ALL_CASES_HEADING)}</h3>", f'<p class="note">{_e(all_note(comp))}</p>',
                        _summary_table(comp.all, "all-table")]
            return "\n".join(out)
    if (run_dir / "table.csv").is_file():
        out.append(_csv_table(run_dir / "table.csv", "main-table"))
    else:
        out.append("<p>No table.csv in this folder.</p>")
    if (run_dir / "table.md").is_file():
        out.append(f"<details><summary>table.md</summary><pre>{_e(_text(run_dir / 'table.md'))}</pre></details>")
    return "\n".join(out)


def _breakdown_section(run_dir: Path) -> str:
    """``breakdown.csv`` as one "mean ± std (n)" table per (grouping, metric), then
    ``breakdown.png`` and ``breakdown.md`` (with the paired comparison)."""
    import pandas as pd
    p = run_dir / "breakdown.csv"
    if not p.is_file():
        return ""
    df = read_cases(p)
    out = ['<h2 id="breakdown">Breakdown per pose and subject</h2>']
    labels = dict(BREAKDOWN_METRICS)
    for (by, metric), g in df.groupby(["by", "metric"], sort=False):
        methods = list(dict.fromkeys(g["method"]))
        rows = []
        for grp, gg in g.groupby("group", sort=False):
            cells = [f"<td>{_e(grp)}</td>"]
            for m in methods:
                r = gg[gg["method"] == m]
                if not len(r):
                    cells.append('<td data-v="">--</td>')
                    continue
                r = r.iloc[0]
                sd = "" if pd.isna(r["std"]) else f" &plusmn; {float(r['std']):.3g}"
                ci = interval_text((r.get("ci_lo", math.nan), r.get("ci_hi", math.nan)), ".3g")
                ci = f" [{ci}]" if ci else ""
                cells.append(f'<td data-v="{float(r["mean"])!r}">{float(r["mean"]):.3g}{sd} ({int(r["n"])}){ci}</td>')
            rows.append(cells)
        out.append(f"<details{' open' if len(out) == 1 else ''}><summary>{_e(labels.get(metric, metric))} per {_e(by)} "
                   f"(mean &plusmn; std (n) [{CI[0]:.0%} interval of the mean])</summary>"
                   f"{_table([str(by), *map(str, methods)], rows)}</details>")
    if (run_dir / "breakdown.png").is_file():
        out.append('<p><img src="breakdown.png" alt="breakdown"></p>')
    if (run_dir / "breakdown.md").is_file():
        out.append("<details><summary>breakdown.md (with the paired SShaDe-Elastic comparison)</summary>"
                   f"<pre>{_e(_text(run_dir / 'breakdown.md'))}</pre></details>")
    return "\n".join(out)


def _link(base: Path, rel: str, inner: str) -> str:
    """``<a href=...>inner</a>`` (:func:`eval.present.report_scope.link_target`), or ``inner``
    alone when ``rel`` may not be linked."""
    href = link_target(base, rel)
    return inner if href is None else f'<a href="{_e(href)}">{inner}</a>'


def _figures_section(run_dir: Path, kind: str, cases, outputs) -> tuple[str, list[str]]:
    """(section, notes): the figures ``*.png`` and ``figures/*.png``; for the ``cases``
    experiment, a case figure only when it is this run's (:func:`eval.present.report_scope.not_current`)."""
    pngs = sorted(p for p in run_dir.glob("*.png") if p.name != "breakdown.png")
    per_case = sorted((run_dir / "figures").glob("*.png")) if (run_dir / "figures").is_dir() else []
    notes = []
    for p in per_case:
        rel = p.relative_to(run_dir).as_posix()
        why = (not_current("figure", p.stem, rel, cases, None if outputs is None else outputs["figures"], stem=True)
               if kind == "cases" else None)
        if why is None:
            pngs.append(p)
        else:
            notes.append(why)
    out = ['<h2 id="figures">Figures</h2>']
    for p in pngs:
        rel = p.relative_to(run_dir).as_posix()
        src = link_target(run_dir, rel)
        if src is not None:
            out.append(f'<figure><a href="{_e(src)}"><img src="{_e(src)}" alt="{_e(rel)}" loading="lazy"></a>'
                       f"<figcaption>{_e(rel)}</figcaption></figure>")
    return ("\n".join(out) if len(out) > 1 else ""), notes


def _view_files(run_dir: Path, cases, outputs) -> tuple[list, list[str]]:
    """([(path, view)] of this run's views, in case order; notes on the others)."""
    views, notes = [], []
    for p in sorted((run_dir / VIEW_DIR).glob("*.js")) if (run_dir / VIEW_DIR).is_dir() else []:
        rel = p.relative_to(run_dir).as_posix()
        try:
            data = read_view(p)
        except (OSError, ValueError):
            log.warning("report: %s is not a view file; left out", p)
            continue
        why = not_current("3D view", str(data["case"]), rel, cases, None if outputs is None else outputs["views"])
        if why is None and link_target(run_dir, rel) is not None:
            views.append((p, data))
        elif why is not None:
            notes.append(why)
    order = {c: i for i, c in enumerate(cases or [])}
    views.sort(key=lambda v: order.get(str(v[1]["case"]), len(order)))
    return views, notes


def _views_section(run_dir: Path, cases, outputs) -> tuple[str, str, list[str]]:
    """(section, script tags, notes) of the 3D views ``report/*.js`` (:mod:`eval.present.meshview`)
    of this run (:func:`_view_files`)."""
    views, notes = _view_files(run_dir, cases, outputs)
    if not views:
        return "", "", notes
    out, tags, total = ['<h2 id="views">3D views</h2>'], [], 0
    for p, data in views:
        total += p.stat().st_size
        rel = p.relative_to(run_dir).as_posix()
        tags.append(f'<script src="{_e(link_target(run_dir, rel))}"></script>')
        shown = ("shown in full" if data["shown_faces"] == data["n_faces"] else
                 f"shown with {data['shown_faces']} faces (vertex clustering, for display only)")
        labels = "".join(f"<div>{_e(m['label'])}{'' if m.get('pos') else ': ' + _e(m['kind'])}"
                         f"{' (restored: its earlier view)' if m.get('carried') else ''}</div>"
                         for m in data["meshes"])
        out.append(f'<div class="view" data-case="{_e(data["case"])}"><h3>{_e(data["case"])}</h3>'
                   f'<div class="view-labels">{labels}</div><canvas></canvas>'
                   f'<p class="note">{_e(data["n_vertices"])} vertices, {_e(data["n_faces"])} faces; {_e(shown)}, '
                   f"{p.stat().st_size / 1e6:.2f} MB ({_e(rel)})</p></div>")
    out.insert(1, f'<p class="note" id="views-status" data-drawn="0">{len(tags)} case(s), {total / 1e6:.2f} MB of '
                  "mesh data next to this page (report.max_faces caps the faces of each mesh). Each mesh is coloured "
                  "by its per-vertex edge-length error (the paper's Fig. 4 measure) on one scale per case, or by its "
                  "distance to the ground truth (buttons above each view). Drag to rotate, wheel to zoom, "
                  "double-click to reset.</p>")
    return "\n".join(out), "\n".join(tags), notes


def _left_out_section(notes: list[str]) -> str:
    """The views and figures not shown (or not redrawn), one line each."""
    if not notes:
        return ""
    return ('<h2 id="left-out">Views and figures left out</h2><ul id="left-out-list">'
            + "".join(f"<li>{_e(n)}</li>" for n in notes) + "</ul>")


def _provenance_section(info: dict) -> str:
    if not info:
        return "<h2 id=\"provenance\">Provenance</h2><p>No run.json in this folder.</p>"
    git = info.get("git") or {}
    rows = [("command", " ".join(map(str, info.get("command") or []))), ("status", info.get("status")),
            ("git commit", git.get("commit")), ("dirty", git.get("dirty")),
            ("modified", ", ".join(git.get("modified") or [])), ("created (UTC)", info.get("created_utc")),
            ("wall (s)", info.get("wall_s")), ("python", info.get("python")), ("platform", info.get("platform")),
            ("cpu count", info.get("cpu_count"))]
    body = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows if v not in (None, ""))
    out = ['<h2 id="provenance">Provenance (run.json)</h2>', f'<table id="provenance-table">{body}</table>']
    params = {str(r.get("name")): r.get("params") for r in info.get("method_sources") or []
              if isinstance(r, dict) and r.get("params") is not None}
    if params:
        out.append(f"<details open><summary>effective parameters (every default and preset value resolved)</summary>"
                   f"<pre>{_e(json.dumps(params, indent=1))}</pre></details>")
    for key in ("seeds", "departures", "compile_s", "packages", "config"):
        if info.get(key):
            text = json.dumps(info[key], indent=1, sort_keys=key != "config")
            out.append(f"<details{' open' if key == 'seeds' else ''}><summary>{key}</summary><pre>{_e(text)}</pre>"
                       "</details>")
    return "\n".join(out)


def _asset(name: str) -> str:
    return (_ASSETS / name).read_text().replace("</script", "<\\/script")


def render_page(run_dir) -> str:
    """The text of ``run_dir/index.html`` (module docstring); reads, writes nothing."""
    run_dir = Path(run_dir)
    info = read_runinfo(run_dir)
    cfg = info.get("config") or {}
    exp = cfg.get("experiment") or {}
    kind = str(exp.get("kind", "cases"))
    dataset = (cfg.get("dataset") or {}).get("name", "") if kind == "cases" else ""  # other kinds read their own data
    title = f"{exp.get('name', run_dir.name)}{': ' + dataset if dataset else ''} ({run_dir.name})"
    cases = run_cases(run_dir, info) if kind == "cases" else None
    outputs = read_outputs(run_dir) if kind == "cases" else None
    views, tags, view_notes = _views_section(run_dir, cases, outputs)
    figures, figure_notes = _figures_section(run_dir, kind, cases, outputs)
    notes = [*(outputs["notes"] if outputs is not None else []), *view_notes, *figure_notes]
    parts = [_main_section(run_dir, kind), views, _breakdown_section(run_dir), figures, _left_out_section(notes),
             _provenance_section(info)]
    files = sorted(p.name + ("/" if p.is_dir() else "") for p in run_dir.iterdir() if not p.name.startswith("."))
    parts.append('<h2 id="files">Files</h2><p>' + " ".join(_link(run_dir, f, _e(f)) for f in files) + "</p>")
    body = "\n".join(p for p in parts if p)
    nav = " ".join(f'<a href="#{a}">{b}</a>' for a, b in (("main", "table"), ("views", "3D"),
                   ("breakdown", "breakdown"), ("figures", "figures"), ("left-out", "left out"),
                   ("provenance", "provenance"))
                   if f'id="{a}"' in body)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><meta name="generator" '
            f'content="{GENERATOR}"><title>{_e(title)}</title><style>{_CSS}</style>\n'
            f"<script>{_asset('errors.js')}</script>\n</head><body>\n"
            f'<div id="js-errors" data-count="0" hidden><b>JavaScript errors on this page:</b></div>\n'
            f"<h1>{_e(title)}</h1><nav>{nav}</nav>\n{body}"
            f"\n{tags}\n<script>{_asset('report.js')}</script>\n</body></html>\n")


def _ours(page: Path) -> bool:
    """Whether ``page`` is absent or was written by this module (generator tag)."""
    try:
        head = _head(page, 2000)
    except FileNotFoundError:
        return True
    except OSError:
        return False
    return f'content="{GENERATOR}"' in head


def _head(path: Path, n: int) -> str:
    """The first ``n`` bytes of the regular file ``path`` as text (a FIFO or a device is
    an OSError, opened without blocking; FileNotFoundError when absent)."""
    return read_prefix(path, n).decode("utf-8", errors="replace")


def write_report(run_dir) -> Path:
    """Write ``run_dir/index.html`` (atomically) from the files of the run folder; returns
    its path. Checks nothing about who may write there (the caller: the running
    evaluator, or :func:`main` through :func:`eval.run.outdir.check_earlier_output`).

    Raises OutputDirError when ``index.html`` exists and this module did not write it
    (kept), OSError when the page cannot be written.
    """
    run_dir = Path(run_dir)
    page = run_dir / PAGE
    if not _ours(page):
        raise OutputDirError(f"{page} was not written by python -m eval.report: left as it is")
    with atomic_write(page, "w") as fh:
        fh.write(render_page(run_dir))
    _write_run_board(run_dir)
    return page


def _write_run_board(run_dir: Path) -> None:
    """``run_dir/leaderboard.md`` when the run read earlier runs' rows (``compare_with``):
    its methods ranked beside theirs (:func:`eval.leaderboard.run_board_markdown`); a
    file of that name this module did not write is left as it is."""
    text = run_board_markdown(run_dir)
    if text is not None and _write_board(run_dir / LEADERBOARD, text):
        record_output_files(run_dir, [LEADERBOARD])


def _write_board(md: Path, text: str) -> bool:
    """Write ``text`` to the leaderboard file ``md`` unless a file there was not written
    by this module (it starts otherwise than :data:`eval.leaderboard.HEADING`: left as it
    is, with a warning). Whether it was written."""
    try:
        ours = not os.path.lexists(md) or _head(md, len(HEADING.encode()) + 1).startswith(HEADING + "\n")
    except OSError:
        ours = False
    if not ours:
        log.warning("%s was not written by python -m eval.report: left as it is", md)
        return False
    with atomic_write(md, "w") as fh:
        fh.write(text)
    return True


def safe_report(run_dir) -> Path | None:
    """:func:`write_report` for the end of an evaluator run: logs and returns None
    instead of raising (the report never fails a run)."""
    try:
        p = write_report(run_dir)
    except Exception as e:  # noqa: BLE001 -- a by-product, like the figures
        log.warning("report not written: %s: %s", type(e).__name__, e)
        return None
    log.info("report %s (%.0f kB; open it in a browser)", p, p.stat().st_size / 1e3)
    return p


def write_index(root) -> Path:
    """``root/index.html``: a link to the page (or the folder) of every run folder
    below ``root`` (a folder with ``run.json``, up to three levels down), with its
    experiment and status (with how many of its stored rows are pending or stale at this checkout,
    :func:`eval.run.stale_rows.check_folders`, or, for a folder run whole, whether it is,
    :func:`eval.run.stale_runs.whole_run_state`). Raises OutputDirError when
    ``root/index.html`` is not ours."""
    root = Path(root)
    runs = sorted({p.parent for p in root.glob("*/run.json")} | {p.parent for p in root.glob("*/*/run.json")}
                  | {p.parent for p in root.glob("*/*/*/run.json")})
    rows = []
    with CommitTrees() as trees:
        stale = {Path(f): ms for f, ms in check_folders(runs, trees, marked=marked_pending).items()}
        whole = {f: whole_run_state(f, trees, find_experiment) for f in whole_run_folders(root) if f in runs}
    for d in runs:
        info = read_runinfo(d)
        rel = d.relative_to(root).as_posix()
        target = f"{rel}/{PAGE}" if (d / PAGE).is_file() else f"{rel}/"
        exp = ((info.get("config") or {}).get("experiment") or {}).get("name", "")
        k = sum(v["stale"] for v in stale.get(d, {}).values())
        j = sum(v["marked"] for v in stale.get(d, {}).values())
        n = sum(v["rows"] for v in stale.get(d, {}).values())
        made = ", ".join(sorted(set().union(*(v["commits"] for v in stale.get(d, {}).values()))))
        changed = sorted(set().union(*(v.get("changed", ()) for v in stale.get(d, {}).values())))
        what = f"; {', '.join(changed[:3])}{' and more' if len(changed) > 3 else ''} changed since" if changed else ""
        word = "pending (listed in its tables)" if mark_word(k, j) == "pending" else f"stale{listed_words(k, j)}"
        status = str(info.get("status", "")) + (f"; {k} of {n} rows {word}, made at {made}{what} "
                                                "(python -m eval.reproduce --check)" if k else "")
        if d in whole and whole[d].stale:
            status += (f"; {'pending' if marked_run(d) is not None else 'stale'}: {whole[d].why} "
                       "(python -m eval.reproduce --check)")
        rows.append([f"<td>{_link(root, target, _e(rel))}</td>", f"<td>{_e(exp)}</td>",
                     f"<td>{_e(status)}</td>", _cell(info.get("n_cases")),
                     f"<td>{_e((info.get('git') or {}).get('commit', ''))[:12]}</td>"])
    if not rows:
        raise OutputDirError(f"no run folder (with run.json) below {root}: no index written")
    page = root / PAGE
    if not _ours(page):
        raise OutputDirError(f"{page} was not written by python -m eval.report: left as it is")
    board = _leaderboard(root)
    text = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><meta name="generator" '
            f'content="{GENERATOR}"><title>{_e(root.name)}</title><style>{_CSS}</style>\n'
            f"<script>{_asset('errors.js')}</script></head><body>\n"
            '<div id="js-errors" data-count="0" hidden><b>JavaScript errors on this page:</b></div>\n'
            f"{board}<h1>{_e(root.name)}: {len(rows)} run folder(s)</h1>\n"
            f"{_table(['Folder', 'Experiment', 'Status', label('n_cases'), 'Commit'], rows, 'runs-table')}\n"
            f"<script>{_asset('report.js')}</script>\n</body></html>\n")
    with atomic_write(page, "w") as fh:
        fh.write(text)
    return page


def _leaderboard(root: Path) -> str:
    """Write ``root/leaderboard.md`` (:mod:`eval.leaderboard`; a file of that name
    not written by it is left as it is) and return the HTML of its method x dataset
    matrix for the top of the index ("" when no run folder has a board)."""
    boards, _ = collect(root)
    if not boards:
        return ""
    _write_board(root / LEADERBOARD, leaderboard_markdown(root))
    head, rows = leaderboard_rows(boards)
    links = " ".join(_link(root, f"{b.folder}/{PAGE}", _e(b.label)) for b in boards)
    cells = [[f"<td>{_e(c)}</td>" for c in r] for r in rows]
    return (f'<h1>Leaderboard</h1>\n<p class="note">Ranked by {_e(RANK_COLUMN[1])} (rank in parentheses: '
            f"{_e(RANK_WORDS)}; no other column ranks); where the data has no ground truth: Volume / EL / FA errors, "
            "not ranked. "
            f"Per dataset, with times and how each method stopped: {_link(root, LEADERBOARD, LEADERBOARD)}; "
            f"runs: {links}.</p>\n{_table(head, cells, 'leaderboard')}\n")


def find_chromium() -> str | None:
    """A headless-capable Chromium/Chrome on PATH (``chromium``, ``chromium-browser``,
    ``google-chrome``), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        exe = shutil.which(name)
        if exe:
            return exe
    return None


#: Flags that give a working WebGL (SwiftShader, software) in headless Chromium.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--use-gl=angle", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--hide-scrollbars", "--no-first-run", "--disable-extensions",
                  "--allow-file-access-from-files")


def chromium(page, *args: str, timeout: float = 60, fragment: str = "") -> subprocess.CompletedProcess:
    """Run headless Chromium (:func:`find_chromium`, :data:`CHROMIUM_FLAGS`) on the file
    ``page`` (its URL with ``fragment``, e.g. ``"#mode=plain"``) with extra ``args`` (e.g.
    ``--dump-dom``); a private profile folder.
    Raises FileNotFoundError without a Chromium, subprocess.TimeoutExpired."""
    import tempfile
    exe = find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium on PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory(prefix="sshade-chromium-") as prof:
        cmd = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={prof}", "--virtual-time-budget=5000", *args,
               Path(page).resolve().as_uri() + fragment]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                              env=dict(os.environ, HOME=prof))


def screenshot(page, png, *, size=(1200, 900), fragment: str = "") -> Path:
    """A PNG of ``page`` as headless Chromium draws it (3D views included, SwiftShader
    WebGL), ``size`` = (width, height) pixels, ``fragment`` as in :func:`chromium`
    (``"#mode=gt"``: the views coloured by the distance to the ground truth); returns ``png``. Raises
    FileNotFoundError without a Chromium, RuntimeError when no PNG was made."""
    png = Path(png).resolve()
    r = chromium(page, f"--screenshot={png}", f"--window-size={size[0]},{size[1]}", fragment=fragment)
    if not png.is_file():
        raise RuntimeError(f"chromium made no screenshot (exit {r.returncode}): {r.stderr[-500:]}")
    return png


def _check_index_dir(path) -> None:
    """``--index DIR`` writes into ``results/`` under ``eval.reproduce``, or into a folder
    of ours (one with an output marker, e.g. a sweep's); OutputDirError otherwise."""
    refuse_results(path, "python -m eval.report --index writes elsewhere only")
    p = Path(os.path.abspath(Path(str(path)).expanduser()))
    res = results_dir()
    if not (res is not None and p == res.resolve() and os.environ.get(REPRODUCE_ENV) == "1") and read_marker(p) is None:
        raise OutputDirError(f"refusing to write {p / PAGE}: {p} is neither results/ (under python -m eval.reproduce) "
                             "nor an output folder of python -m eval or eval.sweeps")


def main(argv=None) -> int:
    """``python -m eval.report [--index DIR] [--screenshot PNG] [RUN_DIR ...]``.

    Returns 0; 2 after one ``error: ...`` line (nothing to do, a folder that is no
    earlier evaluator output, ``results/`` outside ``eval.reproduce``, a page not ours,
    an OSError); 130 on Ctrl-C.
    """
    import sys
    ap = ArgumentParser(prog="python -m eval.report",
                        description="(Re)write index.html, the browser report, of finished evaluator runs.")
    ap.add_argument("dirs", nargs="*", metavar="RUN_DIR", help="a folder written by python -m eval")
    ap.add_argument("--index", metavar="DIR", help="also write DIR/index.html linking every run folder below DIR")
    ap.add_argument("--screenshot", metavar="PNG", help="also save a PNG of the (last) page with headless chromium")
    a = ap.parse_args(list(sys.argv[1:] if argv is None else argv))
    if not a.dirs and not a.index:
        print("usage: python -m eval.report RUN_DIR [RUN_DIR ...] [--index DIR] (--help for details)",
              file=sys.stderr)
        return 2

    def work():
        dirs = [check_earlier_output(d, "eval", "python -m eval.report writes pages of runs outside it")
                for d in a.dirs]  # every folder checked before any page is written
        if a.index:
            _check_index_dir(a.index)
        last = None
        for d in dirs:
            last = write_report(d)
            record_output_files(d, [PAGE])
            print(f"{d}: wrote {PAGE} ({last.stat().st_size / 1e3:.0f} kB)")
        if a.index:
            last = write_index(a.index)
            print(f"wrote {last}")
        if a.screenshot and last is not None:
            print(f"wrote {screenshot(last, a.screenshot)}")
    return run_command(work)


if __name__ == "__main__":
    raise SystemExit(main())
