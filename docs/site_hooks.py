"""mkdocs hooks of the documentation site (mkdocs.yml): the API reference checked complete,
and the leaderboard and the committed tables as generated pages.

* :func:`on_files`: adds ``generated/leaderboard.md`` (``results/leaderboard.md``) and
  ``generated/tables.md`` (every ``results/<run>/table.md``), read at build time, never
  copied into docs/; their links into ``results/`` become the files' repository paths.
* :func:`on_page_markdown`: opens each API page with the table of its packages' public
  names as users import them (``sshade.deform``), each linked to its entry
  (``sshade.pipeline.deform``).
* :func:`on_post_build`: fails the build (``PluginError``) when a name of a package's
  ``__all__`` (:data:`API_PAGES`) has no ``::: module.name`` entry on its API page.
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
#: API page (under docs/) -> the packages whose ``__all__`` it must cover.
API_PAGES = {"api/sshade.md": ("sshade",), "api/defaust.md": ("defaust",), "api/baselines.md": ("baselines",),
             "api/eval.md": ("eval.app", "eval.datasets", "eval.experiments")}
_DIRECTIVE = re.compile(r"^:::\s+([\w.]+)\s*$", re.M)
_LINK = re.compile(r"\[([^\]]+)\]\((?!https?:|#)([^)\s]+)\)")


def missing_api_names(docs_dir: Path) -> list[str]:
    """``package.name`` of every public name (``__all__``) with no ``::: *.name`` entry
    on its API page, sorted; empty when the reference is complete."""
    out = []
    for page, packages in API_PAGES.items():
        text = (docs_dir / page).read_text(encoding="utf-8")
        documented = {path.rsplit(".", 1)[-1] for path in _DIRECTIVE.findall(text)}
        for pkg in packages:
            names = getattr(importlib.import_module(pkg), "__all__", ())
            out += [f"{pkg}.{n} ({page})" for n in names if n not in documented]
    return sorted(out)


def public_names_table(text: str, packages) -> str:
    """A Markdown table of the public names of ``packages`` (``__all__``) as imported,
    each linked to the ``::: module.name`` entry of ``text`` (an API page) that documents it."""
    home = {path.rsplit(".", 1)[-1]: path for path in _DIRECTIVE.findall(text)}
    rows = ["| Import as | Documented as |", "|---|---|"]
    for pkg in packages:
        for n in getattr(importlib.import_module(pkg), "__all__", ()):
            if n in home:
                rows.append(f"| `{pkg}.{n}` | [`{home[n]}`](#{home[n]}) |")
    return "\n".join(rows)


def on_page_markdown(markdown, page, config, files):
    """Put the table of public names before an API page's first section."""
    packages = API_PAGES.get(page.file.src_uri)
    if not packages:
        return markdown
    head, sep, rest = markdown.partition("\n## ")
    return f"{head}\n{public_names_table(markdown, packages)}\n{sep}{rest}" if sep else markdown


def _repository_links(text: str, folder: str) -> str:
    """Relative links of a results file made plain text naming the repository path."""
    return _LINK.sub(lambda m: f"{m.group(1)} (`{folder}/{m.group(2)}`)", text)


def _tables_page() -> str:
    parts = ["# The committed tables", "",
             "Each run's `table.md` under `results/`, as `python -m eval.reproduce` wrote it, read when "
             "this site was built. A row marked pending or stale was made by older code (its "
             "commit is named); the leaderboard ranks the methods.", ""]
    for table in sorted(RESULTS.glob("*/table.md")):
        run = table.parent.name
        body = table.read_text(encoding="utf-8").replace("\n### ", "\n#### ").replace("\n## ", "\n### ")
        body = re.sub(r"^#{1,3} ", "### ", body)
        parts += [f"## `results/{run}`", "", _repository_links(body, f"results/{run}"), ""]
    return "\n".join(parts)


def on_files(files, config):
    """Add the leaderboard and the tables, generated from ``results/``."""
    board = RESULTS / "leaderboard.md"
    if board.is_file():
        text = _repository_links(board.read_text(encoding="utf-8"), "results")
        files.append(File.generated(config, "generated/leaderboard.md", content=text))
    files.append(File.generated(config, "generated/tables.md", content=_tables_page()))
    return files


def on_post_build(config):
    """Fail the build when the API reference leaves out a public name."""
    missing = missing_api_names(Path(config["docs_dir"]))
    if missing:
        raise PluginError("the API reference leaves out: " + ", ".join(missing))
