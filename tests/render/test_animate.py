"""Animations: the frame schedule, GIF read back with Pillow, MP4 when an encoder is installed."""

from __future__ import annotations

import importlib.util
import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageSequence

from tagbot.model import Tag
from tagbot.render import render
from tagbot.render.animate import frame_times, gif_delays, paint_frames
from tagbot.render.api import prepare
from tagbot.render.brush import Brush, RenderError
from tagbot.render.raster import make_view
from tests.render.conftest import constant_speed_line


def gif_frames(path: Path) -> tuple[list[np.ndarray], list[int]]:
    with Image.open(path) as image:
        frames, delays = [], []
        for frame in ImageSequence.Iterator(image):
            delays.append(frame.info["duration"])
            frames.append(np.asarray(frame.convert("L")))
    return frames, delays


@pytest.mark.parametrize(
    ("duration", "fps", "speed", "hold", "frames"),
    [
        (2.0, 25, 1.0, 1.0, 50 + 25),
        (2.0, 25, 2.0, 0.0, 25),
        (1.01, 10, 1.0, 0.5, 11 + 5),
        (0.001, 25, 1.0, 0.0, 1),
    ],
)
def test_frame_count_is_duration_times_rate_over_speed_plus_hold(
    duration: float, fps: float, speed: float, hold: float, frames: int
) -> None:
    timing = frame_times(5.0, duration, fps, speed, hold)
    assert timing.frames == frames == math.ceil(duration * fps / speed) + round(hold * fps)
    assert timing.times[-1] >= 5.0 + duration - 1e-9  # the last drawing frame is complete
    np.testing.assert_allclose(np.diff(timing.times), speed / fps)
    assert timing.seconds == pytest.approx(frames / fps)


def test_gif_delays_add_up_to_whole_centiseconds() -> None:
    for fps in (10, 25, 30, 24):
        delays = gif_delays(100, fps)
        assert all(d % 10 == 0 for d in delays)
        assert sum(delays) == 10 * round(100 * 100 / fps)


def test_gif_frames_match_the_duration_and_rate(tmp_path: Path) -> None:
    motion = constant_speed_line(length=100.0, speed=50.0)  # 2 s, ink added every frame
    out = tmp_path / "line.gif"
    result = render(motion, out, size=(200, 20), fps=20, hold=0.5)
    drawing = math.ceil(motion.t[-1] * 20)
    frames, delays = gif_frames(out)
    # Every drawing frame adds ink; the identical hold frames are merged into the last one, and
    # the count reported is the count in the file.
    assert len(frames) == drawing == result.frames
    assert delays[:-1] == [50] * (drawing - 1)
    assert delays[-1] == 50 * 11
    assert sum(delays) == pytest.approx(1000 * result.seconds)
    ink = [int(np.count_nonzero(f < 128)) for f in frames]
    assert all(b > a for a, b in itertools.pairwise(ink))
    # Frame k shows the motion up to t_k = k / fps: the ink's right end advances 50/20 units.
    scale = 200 / (100 + 2 * 0.02 * 100 + 0.035 * 100)  # px per unit, roughly
    ends = [np.flatnonzero((f < 128).any(axis=0)).max() for f in frames]
    steps = np.diff(ends[2:-3])
    assert np.all(np.abs(steps - 2.5 * scale) <= 2)


def test_animation_speed_and_final_frame(tmp_path: Path, letter_b: Tag) -> None:
    slow, fast = tmp_path / "slow.gif", tmp_path / "fast.gif"
    a = render(letter_b, slow, size=120, fps=25, hold=0)
    b = render(letter_b, fast, size=120, fps=25, speed=2, hold=0)
    duration = letter_b.sample(0.002).duration
    # The schedule's frames, less the identical ones merged; the count is the file's.
    assert a.seconds == pytest.approx(math.ceil(duration * 25) / 25)
    assert b.seconds == pytest.approx(math.ceil(duration * 25 / 2) / 25)
    assert a.frames == len(gif_frames(slow)[0]) <= math.ceil(duration * 25)
    assert b.frames == len(gif_frames(fast)[0]) <= math.ceil(duration * 25 / 2)
    assert sum(gif_frames(fast)[1]) == pytest.approx(1000 * b.seconds, abs=10)
    # The last frame is the whole tag, as the still picture paints it.
    still = tmp_path / "still.png"
    render(letter_b, still, size=120)
    last = gif_frames(slow)[0][-1].astype(int)
    with Image.open(still) as image:
        picture = np.asarray(image.convert("L")).astype(int)
    assert last.shape == picture.shape
    assert np.mean(np.abs(last - picture)) < 1.0


def test_drips_run_down_after_the_pen_has_passed(line: Tag) -> None:
    brush = Brush(drip_chance=1.0)
    painting = prepare(line, drips=True, seed=1, brush=brush)
    end = max(painting.drips, key=lambda d: d.t)
    assert end.t > painting.t1 - 0.2  # the pen lingers at the end of the stroke
    view = make_view(painting.bounds(), size=(300, 60))
    timing = frame_times(painting.t0, painting.duration, 20, 1.0, hold=1.0)
    frames = list(paint_frames(painting, view, timing))
    assert len(frames) == timing.frames
    ink = np.array([f.sum() for f in frames])
    assert np.all(np.diff(ink) >= -1e-3)
    held = ink[timing.drawing - 1 :]
    grow = int(np.ceil(brush.drip_grow * 20))
    assert np.all(np.diff(held[: grow - 2]) > 0)  # the drip still runs down while held
    assert held[-1] == pytest.approx(held[-2])


def test_animation_is_seeded(tmp_path: Path, cae: Tag) -> None:
    a, b = tmp_path / "a.gif", tmp_path / "b.gif"
    render(cae, a, size=160, fps=10, drips=True, seed=4, texture=True)
    render(cae, b, size=160, fps=10, drips=True, seed=4, texture=True)
    assert a.read_bytes() == b.read_bytes()


def test_mp4_without_encoder_is_a_clear_error(
    tmp_path: Path, letter_b: Tag, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = importlib.util.find_spec

    def find_spec(name: str, *args: object) -> object:
        return None if name == "imageio_ffmpeg" else real(name, *args)

    monkeypatch.setattr(importlib.util, "find_spec", find_spec)
    with pytest.raises(RenderError, match=r"imageio-ffmpeg.*tagbot\[video\]"):
        render(letter_b, tmp_path / "b.mp4")
    assert not (tmp_path / "b.mp4").exists()


def test_mp4_frame_count(tmp_path: Path, letter_b: Tag) -> None:
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / "b.mp4"
    result = render(letter_b, out, size=95, fps=10, hold=0.5)
    assert result.width % 2 == 0 and result.height % 2 == 0
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == result.frames


def test_bad_rates_are_refused(tmp_path: Path, letter_b: Tag) -> None:
    with pytest.raises(RenderError, match="too fast for a GIF"):
        render(letter_b, tmp_path / "b.gif", fps=60)
    with pytest.raises(RenderError, match="speed"):
        frame_times(0.0, 1.0, 25, speed=0)
    with pytest.raises(RenderError, match="frames"):
        frame_times(0.0, 1e4, 25)
