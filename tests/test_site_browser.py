"""The documentation site in a browser: built strictly (mkdocs.yml, the [docs] extra), its
home page and a gallery page opened in headless Chromium log nothing to the console, the
gallery page shows the picture its example made, and both screenshots are saved under
build/site-screenshots/ (docs/layout.md shows them)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from eval.report import CHROMIUM_FLAGS, find_chromium

from .conftest import ROOT
from .optional import optional_import

pytestmark = [pytest.mark.slow, pytest.mark.docs]
SHOTS = ROOT / "build" / "site-screenshots"
GALLERY_PAGE = "generated/gallery/plot_04_sshade_vs_arap/index.html"


@pytest.fixture(scope="module")
def site(tmp_path_factory, chromium_on_path) -> Path:
    optional_import("mkdocs")
    out = tmp_path_factory.mktemp("site")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                       capture_output=True, text=True, timeout=1200)
    assert r.returncode == 0, r.stderr[-3000:]
    return out


def _open(page: Path, png: Path) -> tuple[str, list[str]]:
    """The DOM of ``page`` and the console lines of both runs, a screenshot saved to ``png``."""
    with tempfile.TemporaryDirectory(prefix="sshade-chromium-") as prof:
        base = [find_chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={prof}", "--virtual-time-budget=5000",
                "--enable-logging=stderr", "--v=0", "--window-size=1200,900"]
        env = dict(os.environ, HOME=prof)
        shot = subprocess.run([*base, f"--screenshot={png}", page.as_uri()], capture_output=True, text=True,
                              timeout=120, env=env)
        dom = subprocess.run([*base, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120, env=env)
    return dom.stdout, [ln for ln in (shot.stderr + dom.stderr).splitlines() if ":CONSOLE" in ln]


def test_home_and_a_gallery_page_open_without_console_messages(site):
    SHOTS.mkdir(parents=True, exist_ok=True)
    from matplotlib.image import imread
    for page, png in (("index.html", "home.png"), (GALLERY_PAGE, "gallery.png")):
        dom, console = _open(site / page, SHOTS / png)
        assert console == [], f"{page}: {console}"
        assert "<h1" in dom, f"{page}: no page drawn"
        img = imread(SHOTS / png)[..., :3]
        assert (img < 0.9).any(axis=-1).mean() > 0.02, f"{png}: a blank screenshot"
    pictures = re.findall(r'<img[^>]+src="([^"]*mkd_glr_plot_04[^"]*\.png)"', dom)
    assert pictures, "the gallery page shows no picture of its example"
    assert (site / GALLERY_PAGE).parent.joinpath(pictures[0]).resolve().is_file()
