"""The scaling benchmark's tables: ``table.csv`` (every column of every (mesh, size) row)
and ``table.md`` (one table per mesh, under a heading naming how its sizes were built)."""
from __future__ import annotations

import math

from eval.present.measures import columns
from sshade.files import atomic_write

__all__ = ["scaling_markdown", "write_csv", "write_markdown", "MESH_KINDS"]

#: the heading's description of a mesh by its ``remesh`` flag
MESH_KINDS = {True: "clean: LS3 Loop + isotropic remesh", False: "hard: LS3 Loop only"}

#: (column, header, format) of table.md, in order; absent columns are left out
_COLS = columns("scaling")


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _cell(r, key: str, fmt) -> str:
    """One cell of table.md for row ``r`` (a pandas Series)."""
    v = r.get(key)
    if key in ("sshade_total_min_s", "first_call_min_s") and not _missing(v):
        return f"{v:.2f}-{r.get(key.replace('_min_s', '_max_s')):.2f}"
    if key == "lowres_iters_first" and not _missing(v):
        warm = r.get("lowres_iters_mean_warm")
        return f"{v:.0f} / {'-' if _missing(warm) else format(warm, '.1f')}"
    if _missing(v):
        if key == "elastic_total_s" and not _missing(r.get("elastic_total_lower_bound_s")):
            return f"> {r['elastic_total_lower_bound_s']:.0f} (not converged)"
        return "-"
    s = fmt.format(v)
    lower = r.get("speedup_is_lower_bound")
    return "> " + s if key == "speedup" and not _missing(lower) and bool(lower) else s


def _one_table(df) -> list[str]:
    """The lines of one mesh's table (its rows of ``df``, in order)."""
    cols = [c for c in _COLS if c[0] in df.columns and not df[c[0]].isna().all()]
    lines = ["| " + " | ".join(c[1] for c in cols) + " |", "|" + "---:|" * len(cols)]
    for _, r in df.iterrows():
        lines.append("| " + " | ".join(_cell(r, key, fmt) for key, _, fmt in cols) + " |")
    return lines


def scaling_markdown(df) -> str:
    """table.md: per mesh (in the rows' order), ``### <name> (<clean: ... | hard: ...>)``
    and its table, one row per size.

    Parameters
    ----------
    df : pandas DataFrame of the benchmark's rows, with ``mesh`` and ``remesh`` columns
        (times in seconds, memory in MB, errors in % / degrees).

    Returns
    -------
    str, Markdown ending in a newline.
    """
    out = []
    for name in dict.fromkeys(df["mesh"]):
        sub = df[df["mesh"] == name]
        remesh = bool(sub["remesh"].iloc[0])
        out += [f"### {name} ({MESH_KINDS[remesh]})", "", *_one_table(sub), ""]
    return "\n".join(out)


def write_csv(path, df) -> None:
    """Write ``df`` atomically as CSV (``%.6g`` floats, no index)."""
    with atomic_write(path, "w", newline="") as fh:
        df.to_csv(fh, index=False, float_format="%.6g")


def write_markdown(path, df) -> str:
    """Write :func:`scaling_markdown` of ``df`` atomically to ``path``; returns the text."""
    md = scaling_markdown(df)
    with atomic_write(path, "w") as fh:
        fh.write(md)
    return md
