"""PNG rendering, checked by measurable properties of the pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tagbot.model import Tag
from tagbot.render import render, render_array
from tagbot.render.api import prepare
from tagbot.render.brush import Brush, RenderError
from tagbot.render.raster import make_view

INK = 17  # the default ink #111111


def ink_of(rgba: np.ndarray) -> np.ndarray:
    """Ink opacity per pixel of a render with the default ink on white."""
    return (255.0 - rgba[..., 0].astype(float)) / (255.0 - INK)


@pytest.mark.parametrize("name", ["cae", "letter_b"])
def test_ink_coverage_matches_the_swept_area(name: str, request: pytest.FixtureRequest) -> None:
    tag: Tag = request.getfixturevalue(name)
    painting = prepare(tag)
    view = make_view(painting.bounds(), size=600)
    rgba = render_array(tag, size=600)
    assert rgba.shape == (view.height, view.width, 4) and rgba.dtype == np.uint8
    assert np.all(rgba[..., 3] == 255)
    ink = ink_of(rgba)
    # ∫ w ds over the pen-down path: the area a brush sweeps, less overlaps, plus round ends.
    swept = sum(
        float(np.sum(np.hypot(*np.diff(r.xy, axis=0).T) * 0.5 * (r.width[1:] + r.width[:-1])))
        for r in painting.runs
    )
    ratio = ink.sum() / view.scale**2 / swept
    assert 0.9 < ratio < 1.35
    assert 0.02 < ink.mean() < 0.25
    # Anti-aliased: partially covered pixels along the edges.
    assert np.count_nonzero((ink > 0.05) & (ink < 0.95)) > 0.05 * np.count_nonzero(ink > 0.5)


def test_stroke_width_follows_the_width_law(line: Tag) -> None:
    """Across a straight stroke, the inked height of a column is the brush width there: thinner
    where the pen is fast."""
    painting = prepare(line)
    view = make_view(painting.bounds(), size=(1600, 200))
    ink = ink_of(render_array(line, size=(1600, 200)))
    run = painting.runs[0]
    x = run.xy[:, 0]
    inner = (x > 8.0) & (x < 92.0)  # away from the round ends
    columns = np.floor((x[inner] - view.xmin) * view.scale).astype(int)
    measured = ink[:, columns].sum(axis=0) / view.scale  # tag units
    expected = run.width[inner]
    np.testing.assert_allclose(measured, expected, rtol=0.03, atol=1.5 / view.scale)
    order = np.argsort(run.speed[inner])
    assert np.all(np.diff(measured[order]) < 0.5 / view.scale)  # never wider when faster
    fast, slow = order[-1], order[0]
    assert run.speed[inner][fast] > 3 * run.speed[inner][slow]
    assert measured[fast] < 0.6 * measured[slow]


def test_drips_only_below_slow_samples(cae: Tag) -> None:
    seed = 4
    painting = prepare(cae, drips=True, seed=seed)
    assert painting.drips, "this seed should drip"
    bounds = painting.bounds()
    view = make_view(bounds, size=900)
    dry = ink_of(render_array(cae, size=900, bounds=bounds))
    wet = ink_of(render_array(cae, size=900, drips=True, seed=seed, bounds=bounds))
    assert np.all(wet >= dry - 1.0 / 255)
    rows, cols = np.nonzero(wet - dry > 0.5)
    assert len(rows) > 50
    xs, ys = view.centres()
    px, py = xs[cols], ys[rows]
    brush = painting.brush
    slow_xy = np.concatenate(
        [r.xy[r.speed < brush.drip_speed * painting.mean_speed] for r in painting.runs]
    )
    w_max = brush.width * painting.size
    near = np.abs(px[:, None] - slow_xy[None, :, 0]) <= w_max
    below = py[:, None] <= slow_xy[None, :, 1] + w_max
    assert np.all(np.any(near & below, axis=1)), "a drip pixel hangs under no slow sample"
    # And no drip pixel under the fast parts: every fast sample's column stays dry below it.
    fast_xy = np.concatenate([r.xy[r.speed > painting.mean_speed] for r in painting.runs])
    far = np.min(np.abs(fast_xy[:, None, 0] - slow_xy[None, :, 0]), axis=1) > 2 * w_max
    for x, y in fast_xy[far][::10]:
        column = np.abs(px - x) < 0.5 / view.scale
        assert not np.any(column & (py < y)), (x, y)


def test_same_seed_same_picture_other_seed_other_picture(tmp_path: Path, cae: Tag) -> None:
    options = {"size": 400, "drips": True, "texture": True}
    a = render_array(cae, seed=7, **options)
    b = render_array(cae, seed=7, **options)
    c = render_array(cae, seed=8, **options)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    render(cae, tmp_path / "a.png", seed=7, **options)
    render(cae, tmp_path / "b.png", seed=7, **options)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


def test_texture_streaks_the_ink_but_keeps_the_shape(cae: Tag) -> None:
    plain = ink_of(render_array(cae, size=600))
    textured = ink_of(render_array(cae, size=600, texture=True, seed=1))
    inside = plain > 0.99
    assert np.all(textured <= plain + 1.0 / 255)
    assert np.all(textured[plain > 0.5] > 0) and np.all(textured[plain == 0] == 0)
    lighter = 1.0 - textured[inside]
    assert 0.02 < lighter.mean() < 0.4
    assert np.percentile(lighter, 95) > 0.2  # streaks
    none = ink_of(render_array(cae, size=600, texture=True, seed=1, brush=Brush(texture=0.0)))
    assert np.allclose(none, plain, atol=1.0 / 255)


def test_size_dpi_and_transparency(tmp_path: Path, letter_b: Tag) -> None:
    painting = prepare(letter_b)
    xmin, ymin, xmax, ymax = painting.bounds()
    # --size WxH is exact; one number is the longer side.
    assert render_array(letter_b, size=(320, 200)).shape == (200, 320, 4)
    assert max(render_array(letter_b, size=250).shape[:2]) == 250
    # --dpi alone: the tag's physical size (mm).
    rgba = render_array(letter_b, dpi=50.8)  # 2 px per mm
    assert rgba.shape[1] == pytest.approx(2 * (xmax - xmin), abs=1)
    assert rgba.shape[0] == pytest.approx(2 * (ymax - ymin), abs=1)
    out = tmp_path / "b.png"
    render(letter_b, out, dpi=300, size=100, background="none", color="red")
    with Image.open(out) as image:
        assert image.mode == "RGBA"
        assert image.info["dpi"] == pytest.approx((300, 300), abs=0.01)
        pixels = np.asarray(image)
    assert pixels[..., 3].min() == 0 and pixels[..., 3].max() == 255
    assert np.all(pixels[pixels[..., 3] > 0][:, :3] == (255, 0, 0))


def test_bad_requests_are_refused(tmp_path: Path, letter_b: Tag) -> None:
    with pytest.raises(RenderError, match="unknown picture format"):
        render(letter_b, tmp_path / "b.jpg")
    with pytest.raises(RenderError, match="size"):
        render_array(letter_b, size=(0, 10))
    with pytest.raises(RenderError, match="more than"):
        render_array(letter_b, size=(20000, 20000))
    with pytest.raises(RenderError, match="color: not a colour"):
        render_array(letter_b, size=50, color="octarine")
