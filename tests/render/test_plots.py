"""Speed and action-plan plots, and the pictures of a `tagbot draw` run folder."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tagbot.errors import InputError
from tagbot.inputs import load_traces
from tagbot.io.motionfile import write_motion_csv
from tagbot.model import Tag
from tagbot.render import pictures_for_run, plot
from tagbot.render.brush import RenderError
from tagbot.render.plots import (
    exaggerated,
    executed_speed,
    execution_figure,
    load_run,
    plan_figure,
    run_speed_curves,
    save_figure,
    speed_curves,
    speed_figure,
)
from tests.render.conftest import MM_PER_UNIT, TIME_SCALE, write_run_folder


def colours(path: Path) -> np.ndarray:
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB")).reshape(-1, 3).astype(int)


def has_colour(pixels: np.ndarray, hex_: str, tolerance: int = 40, count: int = 50) -> bool:
    rgb = np.array([int(hex_[i : i + 2], 16) for i in (1, 3, 5)])
    return int(np.count_nonzero(np.abs(pixels - rgb).max(axis=1) < tolerance)) >= count


def assert_not_blank(path: Path) -> np.ndarray:
    pixels = colours(path)
    assert np.count_nonzero(pixels.min(axis=1) < 200) > 0.01 * len(pixels)
    return pixels


def test_speed_plot_draws_the_motion_in_the_air(tmp_path: Path) -> None:
    """A plan touching down and lifting off moving: its speed outside the ink window is the
    dashed air curve, inside it the solid one; a plan drawn from rest has no air curve."""
    from tests.model.test_ink import lifted

    plan = lifted(start=0.0)
    curves = speed_curves(Tag((plan,)))
    assert curves.air is not None
    down, up = plan.ink_window(Tag((plan,)).size)
    t, air, ink = curves.air.t, curves.air.y, curves.speed.y
    inside = (t > down + 0.002) & (t < up - 0.002)
    assert np.all(np.isnan(air[inside])) and np.all(np.isfinite(ink[inside]))
    before = t < down - 0.002
    assert np.isfinite(air[before]).any() and np.all(np.isnan(ink[before]))
    assert speed_curves(Tag((lifted(ink=None),))).air is None
    path = tmp_path / "air.png"
    save_figure(speed_figure(curves), path)
    assert has_colour(assert_not_blank(path), "#c62828", count=20)


@pytest.mark.parametrize("name", ["cae", "letter_b"])
def test_speed_plot_shows_each_strokes_lognormal(
    tmp_path: Path, name: str, request: pytest.FixtureRequest
) -> None:
    tag: Tag = request.getfixturevalue(name)
    curves = speed_curves(tag)
    assert len(curves.strokes) == tag.n_strokes
    # |Σ v_j| <= Σ |v_j|: the total speed never exceeds the sum of the stroke components (drawn
    # where above 0.1% of their peak).
    total = np.zeros_like(curves.speed.t)
    for c in curves.strokes:
        total[np.searchsorted(curves.speed.t, c.t)] += c.y
    speed = np.nan_to_num(curves.speed.y)
    assert np.all(speed <= total + 2e-3 * speed.max())
    # Each component's area is its stroke's length (the lognormal has unit area).
    lengths = np.concatenate([p.geometry.length for p in tag.plans])
    areas = [np.trapezoid(c.y, c.t) for c in curves.strokes]
    np.testing.assert_allclose(areas, lengths, rtol=2e-3)
    out = tmp_path / "speed.png"
    plot(tag, out, kind="speed")
    pixels = assert_not_blank(out)
    assert has_colour(pixels, "#c62828")  # total speed
    assert has_colour(pixels, "#2bb3a8")  # strokes


@pytest.mark.parametrize("name", ["cae", "letter_b"])
def test_plan_plot(tmp_path: Path, name: str, request: pytest.FixtureRequest) -> None:
    tag: Tag = request.getfixturevalue(name)
    out = tmp_path / "plan.png"
    plot(tag, out, kind="plan")
    pixels = assert_not_blank(out)
    assert has_colour(pixels, "#f28e2b")  # targets
    assert has_colour(pixels, "#2bb3a8")  # tangent handles
    assert has_colour(pixels, "#2e9e44", count=20)  # dt handles


def test_recorded_speed_is_aligned_with_the_model(tmp_path: Path, letter_b: Tag) -> None:
    """A trace recorded from the tag itself (its motion CSV, slowed 1.5 times) comes back on the
    model's clock at the model's speed."""
    motion = letter_b.sample(0.01)

    class Slowed:
        t = motion.t * 1.5
        xy = motion.xy
        v = motion.v / 1.5
        speed = motion.speed / 1.5
        pen = motion.pen

    recording = tmp_path / "recording.csv"
    write_motion_csv(Slowed, recording)
    traces = load_traces(recording)
    curves = speed_curves(letter_b, traces=traces)
    assert len(curves.measured) == 1
    measured = curves.measured[0]
    model = np.interp(measured.t, curves.speed.t, np.nan_to_num(curves.speed.y))
    assert np.max(np.abs(measured.y - model)) < 0.1 * np.nanmax(curves.speed.y)
    out = tmp_path / "speed.png"
    plot(letter_b, out, traces=traces)
    assert has_colour(assert_not_blank(out), "#f28e2b")


def test_executed_speed_is_smoothed_over_a_window() -> None:
    t = np.arange(0.0, 1.0, 0.001)
    rng = np.random.default_rng(0)
    x = 40.0 * t + rng.normal(0.0, 0.002, len(t))  # 40 mm/s with 2 µm of jitter
    curve = executed_speed(t, np.column_stack([x, 0 * x]))
    assert curve is not None
    assert np.all(np.abs(curve.y - 40.0) < 2.0)
    assert np.diff(curve.t).min() == pytest.approx(0.005)  # half the 10 ms window
    coarse = executed_speed(t[::20], np.column_stack([x, 0 * x])[::20])
    assert coarse is not None and np.diff(coarse.t).min() == pytest.approx(0.02)
    assert executed_speed(t[:3], np.zeros((3, 2))) is None


def test_run_folder_speed_is_aligned_and_in_machine_units(run_dir: Path, cae: Tag) -> None:
    run = load_run(run_dir)
    assert run.mm_per_unit == MM_PER_UNIT and run.time_scale == TIME_SCALE
    curves = run_speed_curves(run)
    assert curves.units == "mm"
    assert len(curves.measured) == len(cae.plans)
    planned = np.nan_to_num(curves.speed.y)
    for measured in curves.measured:
        expected = np.interp(measured.t, curves.speed.t, planned)
        assert np.max(np.abs(measured.y - expected)) < 0.05 * planned.max()
    # The strokes' lognormals on the machine clock and in mm/s: still under the total speed's
    # envelope, with areas equal to the strokes' lengths in mm.
    assert len(curves.strokes) == cae.n_strokes
    total = np.zeros_like(curves.speed.t)
    for c in curves.strokes:
        total[np.searchsorted(curves.speed.t, c.t)] += c.y
    assert np.all(planned <= total + 2e-3 * planned.max())
    lengths = np.concatenate([p.geometry.length for p in cae.plans]) * MM_PER_UNIT
    areas = [np.trapezoid(c.y, c.t) for c in curves.strokes]
    np.testing.assert_allclose(areas, lengths, rtol=2e-2)


def test_pictures_for_run(run_dir: Path) -> None:
    written = pictures_for_run(run_dir)
    names = ["tag.png", "executed.png", "execution.png", "speed.png", "plan.png"]
    assert [p.name for p in written] == names
    for path in written:
        assert path.parent == run_dir
        assert_not_blank(path)
    assert has_colour(colours(run_dir / "speed.png"), "#f28e2b")  # executed speed


def test_pictures_for_a_run_that_did_not_execute(tmp_path: Path, letter_b: Tag) -> None:
    folder = tmp_path / "dry"
    write_run_folder(folder, letter_b, executed=False)
    written = pictures_for_run(folder)
    assert len(written) == 3
    (folder / "plan.json").unlink()
    (folder / "report.json").unlink()
    assert [p.name for p in pictures_for_run(folder)] == ["tag.png", "speed.png"]


def test_bad_run_folders(tmp_path: Path, run_dir: Path) -> None:
    with pytest.raises(InputError, match="not a run folder"):
        load_run(tmp_path / "empty-does-not-exist")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"no plan\.json or motion\.csv"):
        load_run(tmp_path / "empty")
    (run_dir / "report.json").write_text(json.dumps({"placement": {"time_scale": -1}}))
    with pytest.raises(InputError, match="time_scale"):
        load_run(run_dir)
    (run_dir / "report.json").write_text("{}")
    (run_dir / "executed.csv").write_text("time,x\n1,2\n")
    with pytest.raises(InputError, match=r"executed\.csv:1: expected header"):
        load_run(run_dir)
    with pytest.raises(RenderError, match="a plot is a"):
        plot(run_dir, tmp_path / "plot.jpg")


@pytest.mark.parametrize("device", ["grbl", "dynamixel"])
def test_strokes_follow_each_runs_own_time_scale(tmp_path: Path, cae: Tag, device: str) -> None:
    from tagbot.draw import draw

    draw(cae, tmp_path / device, device=device, pictures=False)
    run = load_run(tmp_path / device)
    scales = sorted(s for s, _, _ in run.timing.values())
    assert len(run.timing) == len(cae.plans) and scales[-1] > 1.05 * scales[0]  # runs differ
    curves = run_speed_curves(run)
    total = np.zeros_like(curves.speed.t)
    for c in curves.strokes:
        total[np.searchsorted(curves.speed.t, c.t)] += c.y
    planned = np.nan_to_num(curves.speed.y)
    # With the right clock per run, the planned speed stays under the strokes' envelope (a wrong
    # scale or start moves the lognormals off the speed's peaks).
    assert np.all(planned <= total + 0.03 * planned.max())


def ink(path: Path) -> np.ndarray:
    with Image.open(path) as image:
        return (255.0 - np.asarray(image.convert("L")).astype(float)) / 255.0


def test_executed_picture_shows_what_the_machine_drew(run_dir: Path) -> None:
    """executed.png paints executed.csv: like tag.png when the machine followed the plan, and
    visibly different where it did not."""
    pictures_for_run(run_dir)
    planned, drawn = ink(run_dir / "tag.png"), ink(run_dir / "executed.png")
    assert planned.shape == drawn.shape
    exact = np.abs(planned - drawn)
    assert exact.mean() < 0.01 and np.count_nonzero(exact > 0.5) < 0.02 * np.count_nonzero(
        planned > 0.5
    )
    # The machine drifts 1.5 mm sideways along its second run, and stops 0.8 s halfway.
    lines = (run_dir / "executed.csv").read_text().splitlines()
    rows = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    runs = np.flatnonzero(np.diff(np.concatenate([[0], rows[:, 3] > 0, [0]])))
    a, b = runs[2], runs[3]
    rows[a:b, 1] += np.linspace(0.0, 1.5, b - a)
    middle = (a + b) // 2
    rows[middle:, 0] += 0.8
    rows = np.insert(rows, middle, rows[middle - 1] + [0.4, 0, 0, 0], axis=0)
    text = "\n".join(",".join(repr(float(v)) for v in row[:3]) + f",{int(row[3])}" for row in rows)
    (run_dir / "executed.csv").write_text("t,x,y,pen\n" + text + "\n")
    pictures_for_run(run_dir)
    changed = np.abs(ink(run_dir / "tag.png") - ink(run_dir / "executed.png"))
    assert np.count_nonzero(changed > 0.5) > 5 * np.count_nonzero(exact > 0.5) + 200
    pixels = colours(run_dir / "execution.png")
    assert has_colour(pixels, "#1f6fd1") and has_colour(pixels, "#d62728")


def _legend_boxes(figure: object) -> list:
    legends = list(figure.legends)  # type: ignore[attr-defined]
    legends += [ax.get_legend() for ax in figure.axes if ax.get_legend() is not None]  # type: ignore[attr-defined]
    renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
    return [legend.get_window_extent(renderer) for legend in legends]


def assert_readable(figure: object) -> None:
    """Every axes has labelled axes with units; no legend covers a point of any line; no two
    visible annotations overlap."""
    from matplotlib.collections import LineCollection
    from matplotlib.text import Annotation

    figure.canvas.draw()  # type: ignore[attr-defined]
    renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
    boxes = _legend_boxes(figure)
    assert boxes, "no legend"
    for ax in figure.axes:  # type: ignore[attr-defined]
        for label in (ax.get_xlabel(), ax.get_ylabel()):
            assert label and "(" in label and label.endswith(")"), label
        points = [line.get_xydata() for line in ax.lines]
        points += [
            np.concatenate(c.get_segments())
            for c in ax.collections
            if isinstance(c, LineCollection) and c.get_segments()
        ]
        for image in ax.images:
            x0, x1, y0, y1 = image.get_extent()
            points.append(np.array([[x0, y0], [x1, y1]]))
        for xy in points:
            xy = np.asarray(xy, dtype=float)
            xy = xy[np.all(np.isfinite(xy), axis=1)]
            shown = ax.transData.transform(xy)
            for box in boxes:
                inside = (
                    (shown[:, 0] > box.x0)
                    & (shown[:, 0] < box.x1)
                    & (shown[:, 1] > box.y0)
                    & (shown[:, 1] < box.y1)
                )
                assert not inside.any(), "a legend covers data"
        texts = [t for t in ax.texts if isinstance(t, Annotation) and t.get_visible()]
        extents = [t.get_window_extent(renderer) for t in texts]
        for i, first in enumerate(extents):
            for second in extents[i + 1 :]:
                assert not first.overlaps(second), "two labels overlap"


def test_plots_are_readable(tmp_path: Path, cae: Tag, hello: Tag, run_dir: Path) -> None:
    for tag in (cae, hello):
        assert_readable(speed_figure(speed_curves(tag)))
        figure = plan_figure(tag)
        assert_readable(figure)
        labels = [t for t in figure.axes[0].texts if t.get_text().endswith(" ms")]
        assert sum(t.get_visible() for t in labels) >= min(len(labels), 5)
    # hello has dense Δt labels: some are thinned.
    dense = [t for t in plan_figure(hello).axes[0].texts if t.get_text().endswith(" ms")]
    assert not all(t.get_visible() for t in dense)
    run = load_run(run_dir)
    figure = speed_figure(run_speed_curves(run), title="planned and executed speed")
    assert_readable(figure)
    legend = [t.get_text() for t in figure.legends[0].get_texts()]
    assert any(text.startswith("pen up") for text in legend), legend
    assert sum(1 for p in figure.axes[0].patches) >= len(cae.plans) - 1  # lift bands drawn
    from tagbot.render.raster import make_view

    view = make_view((0.0, 0.0, 10.0, 5.0), size=200)
    a = np.zeros((view.height, view.width))
    a[10:30, 10:100] = 1
    assert_readable(execution_figure(a, np.roll(a, 5, axis=0), view))
    line = np.column_stack([np.linspace(0.0, 10.0, 50), np.full(50, 2.0)])
    figure = execution_figure(a, a, view, paths=([line], [line + np.array([0.0, 0.05])]))
    assert_readable(figure)
    assert len(figure.axes) == 2 and "x4" in figure.axes[1].get_title()  # 0.05 mm shown as 0.2


def test_deviation_is_exaggerated_to_show() -> None:
    planned = [np.column_stack([np.linspace(0.0, 100.0, 11), np.zeros(11)])]
    executed = [np.column_stack([np.linspace(3.0, 97.0, 30), 0.1 * np.sin(np.arange(30.0))])]
    moved, k = exaggerated(planned, executed, target=2.0)
    assert k == pytest.approx(2.0 / np.abs(executed[0][:, 1]).max(), rel=1e-3)
    # Within k times the densified path's spacing (100 / 200,000).
    np.testing.assert_allclose(moved[0][:, 1], k * executed[0][:, 1], atol=1e-3)
    np.testing.assert_allclose(moved[0][:, 0], executed[0][:, 0], atol=k * 5e-4)
    assert exaggerated(planned, [planned[0].copy()], target=2.0)[1] == 1.0
