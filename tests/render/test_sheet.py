"""The demo's variations sheet: the original marked, no empty slot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tagbot.demo import _contact_sheet
from tagbot.gesture import vary
from tagbot.model import Tag


@pytest.mark.parametrize("count", [3, 6])
def test_sheet_marks_the_original_and_fills_every_slot(
    tmp_path: Path, cae: Tag, count: int
) -> None:
    out = tmp_path / "sheet.png"
    _contact_sheet([cae, *vary(cae, count, 5)], out, seed=5, cell=120)
    with Image.open(out) as image:
        rgb = np.asarray(image.convert("RGB")).astype(int)
    rows = 2 if count % 2 == 0 else 1
    columns = -(-count // rows)
    height, width = rgb.shape[:2]
    assert height == rows * 120
    cw = (width - 0) // (rows + columns)
    big = rows * cw
    # The original is framed in red; every variation's cell holds ink (no empty slot).
    red = (rgb[..., 0] > 150) & (rgb[..., 1] < 90) & (rgb[..., 2] < 90)
    assert red[:, :big].sum() > 4 * big and red[:, big:].sum() == 0
    dark = rgb.max(axis=2) < 80
    for i in range(count):
        x, y = big + (i % columns) * cw, (i // columns) * 120
        assert dark[y + 25 : y + 120, x : x + cw].sum() > 100, f"variation {i + 1} is empty"
    assert rows * columns == count
