"""Animation: the tag painted progressively at fixed time steps, as a GIF or an MP4.

Paper §5: the model's samples are spaced in proportion to its speed, so sweeping the brush over
them at a fixed time step animates the gesture as it was made. Frame ``k`` (``k = 1..n``) shows the
motion up to ``t_k = t_0 + k · speed / fps`` (``speed`` > 1 plays faster than real time), so::

    frames = ceil(duration · fps / speed) + round(hold · fps)

where ``duration`` is the motion's (first to last sample, pen lifts included) and the last
``round(hold · fps)`` frames hold the finished tag for ``hold`` seconds. Drips run down over
``Brush.drip_grow`` seconds of the tag's clock from the moment their slow sample is painted, and
are complete in the last frame.

Each frame adds only the brush pieces painted since the previous one (joined to it by one sample),
accumulated by the maximum of coverages, so the cost grows with the frames, not their square.

GIF (Pillow): frame delays are whole centiseconds; each frame's delay is rounded so that the delays
add up to ``frames / fps`` exactly (to the centisecond). Consecutive identical frames (pen lifts,
the hold) are merged into one frame with their delays added, so a GIF holds fewer frames than
counted above (:func:`write_animation` returns the count in the file) but lasts as long. Rates
above 50 fps are refused: browsers slow down GIF frames shorter than 20 ms. The palette is the
256 mixes of the background and the ink, exact.

MP4 (H.264, yuv420p) needs the optional ``imageio-ffmpeg`` package (``pip install
'tagbot[video]'``), which ships its own ffmpeg; the picture's sides are rounded up to even numbers.
GIF and MP4 have no transparency: a transparent background becomes white.
"""

from __future__ import annotations

import importlib.util
import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tagbot.render.brush import Painting, RenderError
from tagbot.render.raster import (
    Rasteriser,
    View,
    compose,
    compound,
    drip_path,
    parse_color,
    spray,
    stroke_path,
    texture_field,
)

__all__ = [
    "MAX_FRAMES",
    "MAX_FRAME_PIXELS",
    "MAX_GIF_FPS",
    "Timing",
    "check_frame_pixels",
    "frame_times",
    "gif_delays",
    "paint_frames",
    "write_animation",
]

MAX_GIF_FPS = 50.0
"""GIF frames shorter than 20 ms are slowed down by browsers."""

MAX_FRAMES = 20_000
"""Refuse animations with more frames than this."""

MAX_FRAME_PIXELS = 2_000_000_000
"""Most pixels of all an animation's frames together (frames times width times height): a GIF keeps
every distinct frame in memory, a byte a pixel (so about 2 GB at most), and painting costs about
as much per pixel of every frame. The default 1200-pixel square allows about 1,390 frames (55 s
at 25 fps)."""

Progress = Callable[[int, int], None]
"""Called with (frames done, frames in all) as frames are painted."""


@dataclass(frozen=True)
class Timing:
    """The frames of an animation: ``drawing`` frames at ``times``, then ``hold`` frames."""

    fps: float
    speed: float
    drawing: int
    hold: int
    times: NDArray[np.float64]
    """``t_k`` of the drawing frames, seconds on the motion's clock."""

    @property
    def frames(self) -> int:
        return self.drawing + self.hold

    @property
    def seconds(self) -> float:
        """How long the animation plays."""
        return self.frames / self.fps


def frame_times(
    t0: float, duration: float, fps: float, speed: float = 1.0, hold: float = 1.0
) -> Timing:
    """The frame schedule of a motion starting at ``t0`` and lasting ``duration`` seconds."""
    for name, value in (("fps", fps), ("speed", speed)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise RenderError(f"{name}: must be a positive number, got {value!r}")
    if not (isinstance(hold, int | float) and math.isfinite(hold) and hold >= 0):
        raise RenderError(f"hold: must be a number of seconds >= 0, got {hold!r}")
    drawing = max(1, math.ceil(duration * fps / speed - 1e-9))
    held = round(hold * fps)
    if drawing + held > MAX_FRAMES:
        raise RenderError(
            f"fps: {drawing + held} frames for {duration:.3g} s at {fps:g} fps and speed"
            f" {speed:g} (max {MAX_FRAMES}); lower --fps or raise --speed"
        )
    times = t0 + np.arange(1, drawing + 1) * (speed / fps)
    return Timing(float(fps), float(speed), drawing, held, times)


def check_frame_pixels(timing: Timing, view: View) -> None:
    """Refuse an animation of more than :data:`MAX_FRAME_PIXELS` before any frame is painted."""
    pixels = timing.frames * view.width * view.height
    if pixels > MAX_FRAME_PIXELS:
        raise RenderError(
            f"size: {timing.frames:,} frames of {view.width}x{view.height} pixels is "
            f"{pixels:,} pixels to paint (max {MAX_FRAME_PIXELS:,}); lower --size or --fps, "
            "or raise --speed"
        )


def gif_delays(frames: int, fps: float) -> list[int]:
    """Per-frame GIF delays in ms, whole centiseconds adding up to ``frames / fps``."""
    ticks = np.round(np.arange(frames + 1) * (100.0 / fps)).astype(np.int64)
    return [int(d) * 10 for d in np.diff(ticks)]


def paint_frames(
    painting: Painting,
    view: View,
    timing: Timing,
    *,
    texture: bool = False,
    seed: int | None = None,
    progress: Progress | None = None,
) -> Iterator[NDArray[np.float32]]:
    """The ink opacity ``(height, width)`` of every frame, in order (hold frames included)."""
    raster = Rasteriser(view)
    factor = None
    if texture:
        if seed is None:
            raise RenderError("seed: the textured brush needs a seed")
        wet = raster.coverage(stroke_path(painting))
        if painting.drips:
            wet = np.maximum(wet, raster.coverage(drip_path(painting)))
        factor = texture_field(painting, view, seed, where=wet > 0)
    scale = timing.fps / timing.speed
    first_frame = [
        np.clip(np.ceil((run.t - painting.t0) * scale - 1e-9), 1, timing.drawing).astype(np.int64)
        for run in painting.runs
    ]
    drip_t = np.array([d.t for d in painting.drips])
    strokes = np.zeros((view.height, view.width), dtype=np.float32)
    total = timing.frames
    last_drips: tuple[float, ...] | None = None
    drips = np.zeros_like(strokes)
    frame = strokes
    for k in range(1, total + 1):
        if k <= timing.drawing:
            pieces = []
            for run, frames in zip(painting.runs, first_frame, strict=True):
                a, b = np.searchsorted(frames, [k, k + 1])
                if b > a:
                    pieces += run.pieces(max(int(a) - 1, 0), int(b))
            if pieces:
                np.maximum(strokes, raster.coverage(compound(*pieces)), out=strokes)
            now = float(timing.times[k - 1])
        else:
            now = float(timing.times[-1]) + (k - timing.drawing) / scale
        if len(drip_t):
            grown = np.clip((now - drip_t) / painting.brush.drip_grow, 0.0, 1.0)
            grown[drip_t > now] = 0.0
            if k == total:
                grown[:] = 1.0
            state = tuple(np.round(grown, 4).tolist())
            if state != last_drips:
                drips = raster.coverage(drip_path(painting, list(state)))
                last_drips = state
        frame = np.maximum(strokes, drips) if len(drip_t) else strokes
        if factor is not None:
            frame = frame * factor
        frame = spray(frame, painting, view, seed)
        if progress is not None:
            progress(k, total)
        yield frame


def _palette(color: object, background: object) -> bytes:
    """The 256 mixes of background and ink, as a GIF palette."""
    if parse_color(background, "background") is None:
        background = "white"
    ramp = np.linspace(0.0, 1.0, 256, dtype=np.float32)[None, :]
    return compose(ramp, color, background)[0, :, :3].tobytes()


def write_animation(
    frames: Iterator[NDArray[np.float32]],
    path: str | os.PathLike[str],
    view: View,
    timing: Timing,
    *,
    color: object = "#111111",
    background: object = "white",
) -> int:
    """Write frames (ink opacities) as a GIF or MP4, by the suffix of ``path``; return the
    number of frames in the file."""
    suffix = os.fspath(path).lower().rsplit(".", 1)[-1]
    if suffix == "gif":
        return _write_gif(frames, path, timing, _palette(color, background))
    if suffix == "mp4":
        return _write_mp4(frames, path, view, timing, color, background)
    else:
        raise RenderError(f"{os.fspath(path)}: an animation is a .gif or an .mp4")


def check_animation(path: str | os.PathLike[str], fps: float) -> None:
    """Refuse what cannot be written before any frame is painted."""
    name = os.fspath(path)
    if name.lower().endswith(".gif") and fps > MAX_GIF_FPS:
        raise RenderError(f"fps: {fps:g} is too fast for a GIF (at most {MAX_GIF_FPS:g})")
    if name.lower().endswith(".mp4") and importlib.util.find_spec("imageio_ffmpeg") is None:
        raise RenderError(
            f"{name}: MP4 needs the optional package imageio-ffmpeg"
            " (pip install 'tagbot[video]'), or write a .gif"
        )


def _write_gif(
    frames: Iterator[NDArray[np.float32]],
    path: str | os.PathLike[str],
    timing: Timing,
    palette: bytes,
) -> int:
    """Write the GIF, consecutive identical frames merged into one (their delays added, as
    Pillow would); return the frames written."""
    from PIL import Image

    delays = gif_delays(timing.frames, timing.fps)
    images: list[Image.Image] = []
    durations: list[int] = []
    previous = b""
    for k, alpha in enumerate(frames):
        data = np.round(np.clip(alpha, 0.0, 1.0) * 255.0).astype(np.uint8)
        if images and data.tobytes() == previous:
            durations[-1] += delays[k]
            continue
        previous = data.tobytes()
        image = Image.frombytes("P", (data.shape[1], data.shape[0]), previous)
        image.putpalette(palette)
        images.append(image)
        durations.append(delays[k])

    images[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=durations,
        loop=0,
        optimize=False,
        disposal=1,
    )
    return len(images)


def _write_mp4(
    frames: Iterator[NDArray[np.float32]],
    path: str | os.PathLike[str],
    view: View,
    timing: Timing,
    color: object,
    background: object,
) -> int:
    import imageio_ffmpeg

    if parse_color(background, "background") is None:
        background = "white"
    writer = imageio_ffmpeg.write_frames(
        os.fspath(path),
        (view.width, view.height),
        fps=timing.fps,
        codec="libx264",
        pix_fmt_out="yuv420p",
        macro_block_size=2,
        ffmpeg_log_level="error",
        output_params=["-movflags", "+faststart"],
    )
    writer.send(None)
    try:
        for alpha in frames:
            writer.send(np.ascontiguousarray(compose(alpha, color, background)[..., :3]).tobytes())
    finally:
        writer.close()
    return timing.frames
