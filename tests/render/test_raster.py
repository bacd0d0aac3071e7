"""PNG rendering, checked by measurable properties of the pixels."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.ndimage import distance_transform_edt

from tagbot.model import Tag
from tagbot.render import render, render_array
from tagbot.render.api import prepare
from tagbot.render.brush import Brush, Painting, RenderError
from tagbot.render.raster import make_view
from tests.render.conftest import Table

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
    assert measured[fast] < 0.7 * measured[slow]


def test_drips_only_below_pools(cae: Tag) -> None:
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
    slow_xy = np.concatenate([r.xy[r.ink > brush.drip_ink] for r in painting.runs])
    w_max = brush.cap * painting.size
    near = np.abs(px[:, None] - slow_xy[None, :, 0]) <= w_max
    below = py[:, None] <= slow_xy[None, :, 1] + w_max
    assert np.all(np.any(near & below, axis=1)), "a drip pixel hangs under no pool"
    # And no drip pixel under the fast parts: every fast sample's column stays dry below it.
    fast_xy = np.concatenate([r.xy[r.ink < brush.flow] for r in painting.runs])
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


def test_texture_runs_along_the_stroke_and_dries_at_speed() -> None:
    """Felt streaks follow the direction of travel (the ink varies across a straight stroke
    far more than along it), and a fast pen leaves out more ink (dry-brush breaks) than a slow
    one."""

    def straight(speed: float) -> Table:
        t = np.arange(0.0, 100.0 / speed + 1e-9, 0.002)
        x = speed * t
        # The mean speed is that of a longer, slower approach: this stroke is fast or slow.
        t_all = np.concatenate([t, t[-1] + 0.002 + np.arange(0.0, 4.0, 0.002)])
        x_all = np.concatenate([x, x[-1] + 25.0 * np.arange(0.0, 4.0, 0.002)])
        xy = np.column_stack([x_all, np.zeros_like(x_all)])
        v = np.gradient(xy, t_all, axis=0)
        pen = np.concatenate([np.ones(len(t)), [0], np.ones(len(t_all) - len(t) - 1)])
        return Table(t_all, xy, v, np.hypot(*v.T), pen.astype(np.int8))

    missing = []
    for speed in (25.0, 200.0):
        motion = straight(speed)
        painting = prepare(motion)
        bounds = (10.0, -3.0, 90.0, 3.0)
        plain = ink_of(render_array(motion, size=(1600, 120), bounds=bounds))
        textured = ink_of(
            render_array(motion, size=(1600, 120), bounds=bounds, texture=True, seed=2)
        )
        rows = np.flatnonzero(plain.min(axis=1) > 0.99)  # inside the stroke all along
        patch = 1.0 - textured[rows]
        missing.append(float(patch.mean()))
        across = patch.mean(axis=1)  # one value per row: streak bands
        along = patch.mean(axis=0)  # one value per column
        if speed == 25.0:
            assert np.var(across) > 4.0 * np.var(along)
        assert painting.runs
    assert missing[1] > 1.5 * missing[0]


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


def measured_widths(
    tag: Tag | Table, size: int = 1400, **options: object
) -> tuple[np.ndarray, Painting]:
    """The rendered stroke's width at every pen-down sample, in tag units: twice the distance
    transform of the inked pixels at the sample's pixel."""
    painting = prepare(tag, **options)
    view = make_view(painting.bounds(), size=size)
    ink = ink_of(render_array(tag, size=size, **options)) > 0.5
    inside = distance_transform_edt(ink)
    xy = np.concatenate([r.xy for r in painting.runs])
    px = np.floor(view.to_pixels(xy)).astype(int)
    return 2.0 * inside[px[:, 1], px[:, 0]] / view.scale, painting


@pytest.mark.parametrize("name", ["cae.json", "letter-b.json", "hello-world-147.json"])
def test_no_lollipops(name: str, hello: Tag, cae: Tag, letter_b: Tag) -> None:
    """The widest 1% of a rendered tag (no drips) is at most 2x its median width, and the
    ends of every run at most 1.5x (the pen starts and stops without lingering)."""
    tag = {"cae.json": cae, "letter-b.json": letter_b, "hello-world-147.json": hello}[name]
    width, painting = measured_widths(tag)
    median = float(np.median(width))
    assert np.percentile(width, 99) <= 2.0 * median
    ends = np.cumsum([len(r) for r in painting.runs])
    caps = width[ends - 1]
    starts = width[np.concatenate([[0], ends[:-1]])]
    assert np.all(caps <= 1.5 * median) and np.all(starts <= 1.5 * median)


def test_width_never_decreases_when_the_pen_dwells_longer() -> None:
    """A stroke along x that stops halfway for longer and longer: the rendered width there
    grows, and saturates at the brush's cap (a pool, never a disc)."""
    brush = Brush()
    measured = []
    for stay in (0.0, 0.02, 0.05, 0.1, 0.3, 1.0, 3.0):
        t = np.arange(0.0, 2.0 + stay + 1e-9, 0.002)
        x = np.where(t < 1.0, 50.0 * t, np.where(t < 1.0 + stay, 50.0, 50.0 * (t - stay)))
        xy = np.column_stack([x, 4.0 * np.sin(x / 30.0)])
        v = np.gradient(xy, t, axis=0)
        motion = Table(t, xy, v, np.hypot(*v.T), np.ones(len(t), dtype=np.int8))
        painting = prepare(motion)
        view = make_view(painting.bounds(), size=2000)
        ink = ink_of(render_array(motion, size=2000)) > 0.5
        column = int(np.floor(view.to_pixels(np.array([50.0, 0.0]))[0]))
        measured.append(ink[:, column].sum() / view.scale)
    steps = np.diff(measured)
    assert np.all(steps >= -1.5 / view.scale), measured  # within a pixel or so
    assert measured[-1] > 1.15 * measured[0]
    cap = brush.cap * painting.size
    assert measured[-1] <= cap * 1.03 + 2 / view.scale


def test_spray_has_soft_edges_and_overspray(cae: Tag) -> None:
    bounds = prepare(cae, brush="spray").bounds()
    marker = ink_of(render_array(cae, size=600, bounds=bounds))
    spray = ink_of(render_array(cae, size=600, bounds=bounds, brush="spray", seed=3))
    soft = lambda ink: np.count_nonzero((ink > 0.05) & (ink < 0.9)) / np.count_nonzero(ink > 0.5)  # noqa: E731
    assert soft(spray) > 3 * soft(marker)
    # Overspray: specks of ink beyond the spray's own (wider, soft) stroke, none for the marker.
    brush = prepare(cae, brush="spray").brush
    view = make_view(bounds, size=600)
    size = prepare(cae).size * view.scale  # the tag's size in pixels
    edge = 0.5 * brush.cap * size + 3 * (0.5 * brush.soft * brush.nib * size)  # + 3 blur sigmas
    far = distance_transform_edt(marker < 0.3) > edge + 4
    assert np.count_nonzero(far & (spray > 0.2)) > 10
    assert np.count_nonzero(far & (marker > 0.2)) == 0
