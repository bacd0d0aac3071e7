"""No beaded ends: along every pen-down run, the widest 1 % of the rendered stroke is at most
twice its median width, for fitted captures (sparse eye-tracker clicks too) and the examples.

The width is the stroke layer's alone (each run rasterised on its own, no drips: drips are a
layer of their own, :attr:`Painting.drips`), measured as twice the distance transform of its
inked pixels at points every half pixel along the run's path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from tagbot.gesture import fit
from tagbot.inputs import load_traces
from tagbot.model import Tag
from tagbot.render.api import prepare
from tagbot.render.raster import Rasteriser, compound, make_view

DATA = Path(__file__).with_name("data")


def widest_over_median(tag: Tag, size: int = 1400) -> list[float]:
    """Per pen-down run: the 99th percentile of its rendered width along its length over the
    median."""
    painting = prepare(tag)
    view = make_view(painting.bounds(), size=size)
    raster = Rasteriser(view)
    ratios = []
    for run in painting.runs:
        inside = distance_transform_edt(raster.coverage(compound(*run.pieces())) > 0.5)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(run.xy, axis=0).T))])
        at = np.linspace(0.0, s[-1], int(s[-1] * view.scale * 2) + 2)
        xy = np.column_stack([np.interp(at, s, run.xy[:, 0]), np.interp(at, s, run.xy[:, 1])])
        px = np.floor(view.to_pixels(xy)).astype(int)
        width = 2.0 * inside[px[:, 1], px[:, 0]]
        ratios.append(float(np.percentile(width, 99) / np.median(width)))
    return ratios


@pytest.fixture(scope="module")
def eye_tracker() -> Tag:
    return fit(load_traces(DATA / "nothub-temptTag-2010_6_7_15_4_51.gml"))


def test_fast_eye_tracker_strokes_have_no_beads(eye_tracker: Tag) -> None:
    assert max(widest_over_median(eye_tracker)) <= 2.0


@pytest.mark.parametrize("name", ["cae", "letter_b", "hello"])
def test_examples_have_no_beads(name: str, request: pytest.FixtureRequest) -> None:
    assert max(widest_over_median(request.getfixturevalue(name))) <= 2.0
