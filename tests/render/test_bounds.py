"""Renders whose cost is over a documented bound are refused before anything is painted."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import tagbot.render.animate as animate
import tagbot.render.api as api
from tagbot.cli import main
from tagbot.io.planfile import save_plan
from tagbot.model.plan import Plan, Tag
from tagbot.render.brush import RenderError
from tests.render.conftest import EXAMPLES


def _plan(tmp_path: Path, delays: list[float]) -> Path:
    """A square drawn with the given delays before its second and third strokes."""
    plan = Plan(
        [[0, 0], [100, 0], [100, 100], [0, 100]],
        [0.0, *delays],
        [-1.6] * 3,
        [0.3] * 3,
        [0.3, 0.2, 0.1],
        [0.1, -0.2, 0.0],
    )
    path = tmp_path / "plan.json"
    save_plan(Tag((plan,), "gamma"), path)
    return path


def _never(*args: object, **kwargs: object) -> None:
    raise AssertionError("work started before the cost was checked")


def test_a_two_hour_tag_is_refused_before_it_is_sampled(capsys, tmp_path, monkeypatch) -> None:
    path = _plan(tmp_path, [3600.0, 3600.0])  # inside the plan limits: 7200.9 s
    monkeypatch.setattr(Tag, "sample", _never)
    out = tmp_path / "tag.png"
    code = main(["render", os.fspath(path), "-o", os.fspath(out)])
    _, err = capsys.readouterr()
    assert code == 2 and not out.exists()
    assert err.startswith(f"tagbot: error: {path}: dt: 7200.88 s of drawing every 0.002 s is ")
    assert err.endswith(
        "3,600,441 samples to paint (max 250,000); a dt of 0.029 s or more paints it\n"
    )


def test_the_sample_bound_is_exact(monkeypatch) -> None:
    from tagbot.io.planfile import load_plan

    cae = load_plan(EXAMPLES / "cae.json")
    samples = api.check_samples(cae, 0.002)
    assert samples == len(cae.sample(0.002).t)
    monkeypatch.setattr(api, "MAX_PAINT_SAMPLES", samples)
    api.prepare(cae, dt=0.002)  # at the bound: painted
    monkeypatch.setattr(api, "MAX_PAINT_SAMPLES", samples - 1)
    with pytest.raises(RenderError, match=f"is {samples:,} samples to paint"):
        api.prepare(cae, dt=0.002)
    with pytest.raises(RenderError, match="the motion has"):
        api.prepare(cae.sample(0.002))


def test_an_animation_over_the_pixel_bound_is_refused_before_a_frame(
    capsys, tmp_path, monkeypatch
) -> None:
    path = _plan(tmp_path, [100.0, 100.0])  # 200.9 s: 5,047 frames at 25 fps, the last second held
    monkeypatch.setattr(animate, "paint_frames", _never)
    monkeypatch.setattr(api, "paint_frames", _never)
    out = tmp_path / "tag.gif"
    code = main(["render", os.fspath(path), "-o", os.fspath(out), "--size", "1200x800"])
    _, err = capsys.readouterr()
    assert code == 2 and not out.exists()
    assert err == (
        f"tagbot: error: {path}: size: 5,047 frames of 1200x800 pixels is 4,845,120,000 pixels "
        "to paint (max 2,000,000,000); lower --size or --fps, or raise --speed\n"
    )


def test_the_frame_pixel_bound_is_exact(tmp_path, monkeypatch) -> None:
    from tagbot.io.planfile import load_plan

    cae = load_plan(EXAMPLES / "cae.json")
    out = tmp_path / "cae.gif"
    timing = animate.frame_times(cae.start, cae.end - cae.start, 10)
    pixels = timing.frames * 40 * 30
    monkeypatch.setattr(animate, "MAX_FRAME_PIXELS", pixels)
    api.render(cae, out, size=(40, 30), fps=10)
    monkeypatch.setattr(animate, "MAX_FRAME_PIXELS", pixels - 1)
    with pytest.raises(RenderError, match=f"is {pixels:,} pixels to paint"):
        api.render(cae, out, size=(40, 30), fps=10)
