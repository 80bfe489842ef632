"""The outputs of the ``cases`` experiment that follow each finished case
(:class:`CaseOutputs`): ``cases.csv``, then for the first cases the figure and the 3D
view, from the fresh runs' vertices, the store's meshes, or (``figures.rerun_restored``)
a rerun of a restored run without a stored mesh whose vertices are the stored run's bit
for bit; ``report/outputs.json`` names what was drawn and why the rest was not.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py)."""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np

from eval.experiments.cases.pair import run_pair
from eval.present.figures import FIGURE_RECORDS, case_figure_path, write_case_figure
from eval.present.meshview import OUTPUTS, VIEW_DIR, case_view_path, write_case_view, write_outputs
from eval.present.render import png_text, set_png_text
from eval.run.result_store import output_digest
from eval.run.spec import FigureOptions, ReportOptions
from eval.tables import write_cases
from sshade.errors import SShaDeError

__all__ = ["CaseOutputs", "former_key", "rerun_output"]

log = logging.getLogger("eval")


class _NoReference:
    """The references of a rerun for an output: none (its row is the stored one)."""

    @staticmethod
    def metrics(m, U) -> dict:
        return {}


def rerun_output(m, name: str, case, guard: dict) -> np.ndarray:
    """The deformed vertices (n, 3) float64 of method ``m`` (row label ``name``) run again
    on ``case`` exactly as a row runs it (:func:`eval.experiments.cases.pair.run_pair`,
    ``guard['timeout_s']``), for an output (figure, 3D view) of a restored run whose
    record keeps no mesh; its row is dropped (the stored one stands), nothing is stored,
    no reference is scored. SShaDeError: the run failed (the row's error)."""
    row, U, _ = run_pair(m, name, case, _NoReference(), guard)
    if U is None or row.get("error"):
        raise SShaDeError(row.get("error") or "no result")
    return np.asarray(U, dtype=np.float64)


def former_key(rec: dict) -> str | None:
    """The key of an earlier record of the same vertices as the stored record ``rec``:
    the key it had before this run gave it a new one (re-keyed,
    :func:`eval.run.stale_rows.rekey_record`, ``rekeyed``; or kept because its reference
    came out bit for bit the same,
    :func:`eval.experiments.cases.reference_cutoff.keep_if_reproduced`, ``reproduced``),
    or the record whose output bytes its run gave again (``same_output_as``); None for any
    other record. An earlier figure or 3D view stamped with that key shows these vertices."""
    for how, name in (("rekeyed", "from_key"), ("reproduced", "from_key"), ("same_output_as", "key")):
        k = rec[how].get(name) if isinstance(rec.get(how), dict) else None
        if isinstance(k, str) and k:
            return k
    return None


class CaseOutputs:
    """What follows each finished case: ``cases.csv`` (the rows of every finished pair, in
    (case, method) order) and, for the first ``figures.max_cases`` / ``report.view_cases``
    cases, the figure and the 3D view (restored pairs' meshes read from the store), with
    ``report/outputs.json`` (:func:`eval.present.meshview.write_outputs`) naming the views and
    figures this run wrote and saying why the others were not: the report shows only
    those. A figure or view of this run's case that is not (re)drawn has its earlier
    file removed (a resumed run keeps an earlier run's files), except a figure stamped
    with exactly the records this run restored (:meth:`_figure`)."""

    def __init__(self, figures: FigureOptions, report: ReportOptions, s, plan: dict, done: dict, *,
                 rerun: bool = False):
        self.s, self.plan, self.done = s, plan, done
        self.n_fig = figures.max_cases if figures.enabled else 0  # figures.enabled / max_cases
        self.n_view, self.max_faces = report.views, report.max_faces  # report.view_cases, max_faces
        self.views, self.figures, self.notes = {}, {}, {}  # case index -> relative path; -> texts
        self.rerun = rerun  # figures.rerun_restored, in this process (no cluster array)
        self.deferred = {}  # case index -> (deformed, unknown): drawn by redraw(), after every pair
        self._record()  # at once: an earlier run's record never speaks for this run

    def wants_meshes(self, ci: int) -> bool:
        return ci < max(self.n_fig, self.n_view)

    def rows(self, upto: int) -> list[dict]:
        return [self.done[ci, mi]["row"] for ci in range(upto) for mi in self.plan[ci] if (ci, mi) in self.done]

    def case_done(self, ci: int, fresh: dict) -> None:
        """Case ``ci`` finished; ``fresh``: method index -> deformed vertices (or None) of
        the pairs just run."""
        import pandas as pd

        s = self.s
        write_cases(pd.DataFrame(self.rows(len(s.cases))), s.out_dir)  # partial results survive a crash
        if not self.wants_meshes(ci):
            return
        deformed, unknown = {}, []  # method -> deformed vertices; restored without a mesh
        for mi in self.plan[ci]:
            name = s.names[mi]
            if mi in fresh:
                deformed[name] = fresh[mi]
                continue
            if (ci, mi) not in self.done:  # left at the run's stop, never stored: no row, no mesh
                continue
            deformed[name] = s.store.load_mesh(self.done[ci, mi], len(s.cases[ci].V))
            if deformed[name] is None and not self.done[ci, mi]["row"].get("error"):
                unknown.append(name)  # restored without its mesh (store.meshes=false)
        if unknown and self.rerun and ci < self.n_fig and not self._earlier_figure_holds(ci):
            self.deferred[ci] = (deformed, unknown)  # no rerun beside the timed runs of other cases
            return
        self._draw(ci, deformed, unknown, {})

    def redraw(self, deadline: float | None = None) -> None:
        """The outputs of the cases :meth:`case_done` deferred, once every pair has run (no
        timed run beside): each restored run without a stored mesh is run again in this
        process (:func:`rerun_output`: nothing stored, its row discarded), and its
        vertices are shown only when their :func:`output_digest` is the
        stored record's ``output``: the figure shows the very vertices its rows measured.
        A rerun that fails, gives other vertices, or would end past ``deadline``
        (``time.perf_counter()`` seconds; its expected cost from the record's ``time_s``)
        leaves that method unknown, and the note says why."""
        s = self.s
        for ci in sorted(self.deferred):
            deformed, unknown = self.deferred.pop(ci)
            case, why = s.cases[ci], {}
            for name in list(unknown):
                rec = self.done[ci, s.names.index(name)]
                if s.left.get((case.name, name), ("", None, False))[2]:
                    continue  # an earlier build's row: this case data cannot give its vertices
                U, why[name] = self._rerun(ci, name, rec, deadline)
                if U is not None:
                    deformed[name] = U
                    unknown.remove(name)
            self._draw(ci, deformed, unknown, why)

    def _rerun(self, ci: int, name: str, rec: dict, deadline: float | None):
        """``(U, why)``: the vertices (n, 3) of ``name``'s rerun on case ``ci`` when they
        are the stored record ``rec``'s bit for bit (``why`` then says so), else ``(None,
        why)``."""
        s, case = self.s, self.s.cases[ci]
        expected = rec["row"].get("time_s")
        expected = float(expected) if isinstance(expected, (int, float)) and expected == expected else 0.0
        if deadline is not None and time.perf_counter() + expected > deadline:
            return None, f"no time left for a rerun of {name} (about {expected:.0f} s)"
        t0 = time.perf_counter()
        try:
            U = rerun_output(s.methods[s.names.index(name)], name, case, s.guard)
        except SShaDeError as e:
            log.warning("%s %s: rerun for the figure failed: %s", case.name, name, e)
            return None, f"its rerun of {name} failed"
        wall = time.perf_counter() - t0
        if output_digest(U) != rec.get("output"):
            log.warning("%s %s: rerun for the figure gave other vertices than the stored run", case.name, name)
            return None, f"its rerun of {name} gave other vertices than the stored run"
        log.info("%s %s: rerun for the figure in %.1f s gave the stored run's vertices bit for bit", case.name,
                 name, wall)
        return U, f"{name} rerun ({wall:.0f} s, the stored vertices bit for bit)"

    def _draw(self, ci: int, deformed: dict, unknown: list, why: dict) -> None:
        """Case ``ci``'s figure and 3D view from ``deformed`` (method -> vertices, or
        None); ``unknown``: the restored runs with no vertices; ``why``: method -> what
        the rerun for this output gave (a note)."""
        s = self.s
        case = s.cases[ci]
        not_run, keys, earlier = self._records(ci)
        results = {n: deformed.get(n) for n in s.names}
        if why:
            note = f"outputs of case {case.name}: " + "; ".join(why[n] for n in sorted(why))
            self.notes.setdefault(ci, []).append(note)
        if ci < self.n_fig:  # out_dir/figures/<case>.png (eval/present/figures.py)
            self._figure(ci, results, not_run, unknown)
        if ci < self.n_view:  # out_dir/report/<case>.js, for index.html (eval/report.py)
            other = [n for n in unknown if s.left.get((case.name, n), ("", None, False))[2]]  # an earlier build's
            p = write_case_view(case, results, s.out_dir, max_faces=self.max_faces, not_run=not_run,
                                stored=[n for n in unknown if n not in other], other_data=other, keys=keys,
                                aliases=earlier)
            self._kept(ci, "3D view", p, case_view_path(s.out_dir, case.name))
        self._record()

    def _records(self, ci: int) -> tuple[list, dict, dict]:
        """``(not_run, keys, earlier)`` of case ``ci``: the methods not run on it, method ->
        its record's key, method -> the key of an earlier record of the same vertices
        (:func:`former_key`) or its own."""
        s = self.s
        not_run = [n for m, n in zip(s.methods, s.names) if not s.runs_on(ci, m)]  # "not run", not "failed"
        keys = {s.names[mi]: self.done[ci, mi].get("key") for mi in self.plan[ci] if (ci, mi) in self.done}
        earlier = {s.names[mi]: former_key(self.done[ci, mi]) or keys[s.names[mi]]
                   for mi in self.plan[ci] if (ci, mi) in self.done}  # the same vertices under an earlier key
        return not_run, keys, earlier

    def _stamps(self, ci: int) -> tuple[str, str, dict]:
        """``(stamp, before, keys)``: the :data:`FIGURE_RECORDS` text of case ``ci``'s figure
        under its records' keys, and under their earlier keys."""
        not_run, keys, earlier = self._records(ci)
        stamp = json.dumps({"records": keys, "not_run": sorted(not_run)}, sort_keys=True)
        before = json.dumps({"records": earlier, "not_run": sorted(not_run)}, sort_keys=True)
        return stamp, before, keys

    def _earlier_figure_holds(self, ci: int) -> bool:
        """Whether case ``ci``'s figure file is stamped with the records this run has for
        it (under their keys or their earlier ones): it shows their vertices."""
        stamp, before, keys = self._stamps(ci)
        try:
            path = case_figure_path(self.s.out_dir / "figures", self.s.cases[ci].name)
            return bool(all(keys.values()) and path.is_file() and png_text(path).get(FIGURE_RECORDS) in (stamp, before))
        except (OSError, SShaDeError):
            return False

    def _figure(self, ci: int, results: dict, not_run: list, unknown: list) -> None:
        """Case ``ci``'s figure, stamped with the records it shows (:data:`FIGURE_RECORDS`,
        a PNG text chunk). When some restored run has no vertices (``unknown``), an earlier
        run's figure stamped with exactly these records (their keys, or the keys they had
        before they were re-keyed, :func:`eval.run.stale_rows.rekey_record`) is kept,
        stamped anew, and noted as such; else removed."""
        s, case = self.s, self.s.cases[ci]
        path = case_figure_path(s.out_dir / "figures", case.name)
        stamp, before, _ = self._stamps(ci)
        if not unknown:
            p = write_case_figure(case, results, s.out_dir / "figures", not_run=not_run)
            try:
                p = p and set_png_text(p, {FIGURE_RECORDS: stamp})
            except (OSError, SShaDeError) as e:
                log.warning("figure %s not stamped with its records: %s", p, e)
            return self._kept(ci, "figure", p, path)
        same = self._earlier_figure_holds(ci)
        try:
            if same and png_text(path).get(FIGURE_RECORDS) != stamp:
                set_png_text(path, {FIGURE_RECORDS: stamp})  # the same records under their new keys
        except (OSError, SShaDeError):
            same = False
        if same:
            self._kept(ci, "figure", path, path)
            note = (f"figure of case {case.name} kept from the earlier run: it shows the same stored records "
                    f"(the restored runs of {', '.join(unknown)} have no stored mesh)")
            log.info("%s", note)
            self.notes.setdefault(ci, []).append(note)
            return None
        return self._kept(ci, "figure", None, path, f"not redrawn: its restored runs of {', '.join(unknown)} have "
                          "no stored mesh (store.meshes=true keeps them)")

    def _kept(self, ci: int, what: str, path, earlier: Path, why: str = "not drawn (eval.log says why)") -> None:
        """Record case ``ci``'s ``what`` (figure, 3D view) at ``path`` as this run's; when
        ``path`` is None (not drawn), a note saying ``why``, and the file ``earlier`` of an
        earlier run removed, so that it is never shown as this run's."""
        if path is not None:
            (self.figures if what == "figure" else self.views)[ci] = Path(path).relative_to(self.s.out_dir).as_posix()
            return
        note = f"{what} of case {self.s.cases[ci].name} {why}"
        if earlier.is_file():
            try:
                earlier.unlink()
                note += f"; the earlier run's {earlier.relative_to(self.s.out_dir).as_posix()} was removed"
            except OSError as e:
                note += f"; the earlier run's file could not be removed ({e.strerror})"
        log.info("%s", note)
        self.notes.setdefault(ci, []).append(note)

    def _record(self) -> None:
        """``report/outputs.json`` (when this run draws figures or views, or an earlier
        run left one); a failure to write it is logged, the run goes on."""
        s = self.s
        if not (self.n_fig or self.n_view or (s.out_dir / VIEW_DIR / OUTPUTS).exists()):
            return
        names = [c.name for c in s.cases]
        try:
            write_outputs(s.out_dir, names, {names[ci]: p for ci, p in sorted(self.views.items())},
                          {names[ci]: p for ci, p in sorted(self.figures.items())},
                          [n for ci in sorted(self.notes) for n in self.notes[ci]])
        except OSError as e:
            log.warning("%s not written: %s", s.out_dir / VIEW_DIR / OUTPUTS, e)
