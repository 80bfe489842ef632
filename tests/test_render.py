"""eval/present/render.py: PNG files (text chunks, size) beside the images they hold."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.errors import SShaDeError


def test_png_text_round_trips_and_pillow_reads_it(tmp_path):
    from PIL import Image

    from eval.present.render import png_size, png_text, save_png, set_png_text
    p = save_png(tmp_path / "a.png", np.full((3, 4, 3), 7, np.uint8))
    set_png_text(p, {"k": "one"})
    set_png_text(p, {"k": "two", "other": "x"})  # replaces k, adds other
    assert {k: v for k, v in png_text(p).items() if k in ("k", "other")} == {"k": "two", "other": "x"}
    assert Image.open(p).text["k"] == "two" and png_size(p) == (4, 3)
    assert (np.asarray(Image.open(p).convert("RGB")) == 7).all()  # the image itself unchanged
    p.write_bytes(p.read_bytes()[:-5])
    with pytest.raises(SShaDeError):
        png_text(p)
