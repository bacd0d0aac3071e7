"""SVG output parsed back by a standard XML parser and by svgelements."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import svgelements

from tagbot.model import Tag
from tagbot.render import render
from tagbot.render.api import prepare
from tagbot.render.raster import make_view

NS = {"svg": "http://www.w3.org/2000/svg"}


def groups(path: Path) -> dict[str, list[ET.Element]]:
    root = ET.parse(path).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    return {g.get("id", ""): g.findall("svg:path", NS) for g in root.findall("svg:g", NS)}


@pytest.mark.parametrize("name", ["cae", "letter_b"])
def test_one_outline_per_run_with_the_motions_bounds(
    tmp_path: Path, name: str, request: pytest.FixtureRequest
) -> None:
    tag: Tag = request.getfixturevalue(name)
    out = tmp_path / "tag.svg"
    result = render(tag, out)
    found = groups(out)
    assert len(found["strokes"]) == len(tag.plans)
    assert "drips" not in found
    painting = prepare(tag)
    view = make_view(painting.bounds(), size=None, units=tag.units)
    assert (result.width, result.height) == (view.width, view.height)
    document = svgelements.SVG.parse(str(out))
    paths = [e for e in document.elements() if isinstance(e, svgelements.Path)]
    assert len(paths) == len(tag.plans)
    w_max = painting.brush.cap * painting.size
    for run, element in zip(painting.runs, found["strokes"], strict=True):
        xmin, ymin, xmax, ymax = svgelements.Path(element.get("d")).bbox()
        # Back to the tag's coordinates (the SVG's y points down from the view's top).
        box = np.array([xmin + view.xmin, view.ymax - ymax, xmax + view.xmin, view.ymax - ymin])
        lo = (run.xy - run.width[:, None] / 2).min(axis=0)
        hi = (run.xy + run.width[:, None] / 2).max(axis=0)
        np.testing.assert_allclose(box, [*lo, *hi], atol=0.03 * w_max)


def test_drips_texture_and_physical_size(tmp_path: Path, cae: Tag) -> None:
    out = tmp_path / "tag.svg"
    result = render(cae, out, drips=True, seed=4, texture=True)
    assert result.drips > 0
    found = groups(out)
    assert len(found["strokes"]) == 3
    assert len(found["drips"]) == result.drips
    root = ET.parse(out).getroot()
    assert root.get("width", "").endswith("mm") and root.get("height", "").endswith("mm")
    turbulence = root.find(".//svg:feTurbulence", NS)
    assert turbulence is not None and turbulence.get("seed") == "4"
    again = tmp_path / "again.svg"
    render(cae, again, drips=True, seed=4, texture=True)
    assert out.read_bytes() == again.read_bytes()
    assert len(list(svgelements.SVG.parse(str(out)).elements())) > 0


def test_pixel_size_and_transparent_background(tmp_path: Path, letter_b: Tag) -> None:
    out = tmp_path / "b.svg"
    render(letter_b, out, size=(300, 400), background="none")
    root = ET.parse(out).getroot()
    assert (root.get("width"), root.get("height")) == ("300", "400")
    assert root.find("svg:rect", NS) is None
