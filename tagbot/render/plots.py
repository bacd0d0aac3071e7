"""Plots like the paper's Figures 4, 6 and 12, and the pictures of a ``tagbot draw`` run folder.

- **Speed** (:func:`speed_figure`): the tag's speed ``|v(t)|`` over time with, under it, each
  stroke's weighted lognormal ``D_j · Λ(t; t0_j, μ_j, σ_j)`` (``D_j`` the length of stroke ``j``'s
  curve), and a measured speed when there is one: a recording's (input traces with timing, mapped
  onto the model's clock by the scale and offset that best match the velocities, as for the
  velocity SNR of :mod:`tagbot.metrics`), or a machine's executed motion (run folders). Pen lifts
  are shaded.
- **Action plan** (:func:`plan_figure`): virtual targets (squares), the polygon joining them
  (dotted), the trajectory, tangent handles at both ends of every stroke showing its departure
  angle ``alpha + phi1`` and arrival angle ``alpha + phi2`` (ΣΛ*: the departure handle
  ``alpha − phi`` only, the arc's end tangent being its mirror), and ``Δt`` handles: a segment at
  each stroke's first target whose length is proportional to the stroke's ``dt``, labelled in ms.

**Run folders** written by ``tagbot draw``: ``plan.json`` (tag units), ``motion.csv`` (planned
setpoints ``t,x,y,vx,vy,speed,pen``, machine mm and seconds), ``executed.csv`` (``t,x,y,pen`` on the
device's clock), ``report.json`` with ``placement.mm_per_unit`` and ``placement.time_scale``
(machine speed = tag speed × mm_per_unit / time_scale, machine time = tag time × time_scale) and
``runs`` (``plan``, ``planned_start``, ``executed_start`` per pen-down run). The executed pen-down
runs are matched to those in order (as :func:`tagbot.metrics.compare_execution` does) and shifted
by ``planned_start − executed_start`` onto the planned clock. Each run has its own time scale:
``placement.runs`` gives, per run, ``scale``, ``tag_start`` (the tag-clock instant of its first
point) and ``start`` (the job-clock instant of that point), and stroke ``j`` of plan ``p`` is
drawn at machine time ``start + scale · (t − tag_start)`` (older reports without it:
``planned_start(p) + time_scale · (t − plans[p].start)``). The executed speed is
the central difference of the executed positions over a window of ``max(10 ms, 2 × the median
sample interval)``, on a grid of half that window (:func:`executed_speed`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from numpy.typing import NDArray

from tagbot.errors import InputError
from tagbot.model.lognormal import lognormal
from tagbot.model.plan import Tag
from tagbot.render.brush import MotionLike, RenderError

__all__ = [
    "PLOT_KINDS",
    "Curve",
    "RunFolder",
    "SpeedCurves",
    "exaggerated",
    "executed_motion",
    "executed_speed",
    "execution_figure",
    "load_run",
    "pictures_for_run",
    "plan_figure",
    "plot",
    "plot_format",
    "recorded_speed",
    "run_speed_curves",
    "save_figure",
    "speed_curves",
    "speed_figure",
]

Array = NDArray[np.float64]

PLOT_KINDS = ("speed", "plan")
AIR_SPEED = 1e-3
"""Pen-up samples faster than this fraction of the peak speed are drawn as moving in the air
(the slower rest of a lognormal's tail is not)."""

EXECUTED_WINDOW = 0.01
"""The executed speed's smallest differencing window, seconds (a 1 ms record of 1/80 mm steps
is then within about 1 mm/s)."""

STROKE_COLOR = "#2bb3a8"
SPEED_COLOR = "#c62828"
MEASURED_COLOR = "#f28e2b"
TARGET_COLOR = "#f28e2b"
DT_COLOR = "#2e9e44"
TRACE_COLOR = "#b0b0b0"
LIFT_COLOR = "#000000"
LIFT_ALPHA = 0.06


@dataclass(frozen=True)
class Curve:
    """A sampled curve."""

    t: Array
    y: Array


@dataclass(frozen=True)
class SpeedCurves:
    """What :func:`speed_figure` draws."""

    speed: Curve
    """The model's (or the plan's) speed; NaN where the pen is up."""
    strokes: list[Curve]
    """Each stroke's weighted lognormal, over its own window."""
    measured: list[Curve] = field(default_factory=list)
    """Recorded or executed speed, one curve per pen-down run."""
    measured_label: str = "recorded"
    lifts: list[tuple[float, float]] = field(default_factory=list)
    """Pen-up intervals to shade."""
    units: str = "mm"
    speed_label: str = "speed |v|"
    air: Curve | None = None
    """The speed where the pen moves in the air (before a touch-down or after a lift-off in
    motion, a plan's ``ink`` window); NaN elsewhere. None: nothing moves pen up."""


def _stroke_curves(
    tag: Tag,
    t: Array,
    offsets: Sequence[float] | None = None,
    time_scale: float | Sequence[float] = 1.0,
    speed_scale: float = 1.0,
) -> list[Curve]:
    """Each stroke's ``D·Λ``, on the grid ``t`` (mapped to the tag's clock by
    ``(t − offsets[p]) / time_scale`` for plan ``p``), over the window where it exceeds 0.1% of
    its peak; values times ``speed_scale``."""
    curves = []
    for p, plan in enumerate(tag.plans):
        offset = 0.0 if offsets is None else offsets[p]
        scale = time_scale if isinstance(time_scale, int | float) else time_scale[p]
        tau = (t - offset) / scale
        length = plan.geometry.length
        for j in range(plan.n_strokes):
            # Roughly where Λ is above 1e-3 of its peak (a lognormal in ln(t − t0)).
            spread = plan.sigma[j] * math.sqrt(2.0 * math.log(1e3))
            lo = plan.onsets[j] + math.exp(plan.mu[j] - plan.sigma[j] ** 2 - spread)
            hi = plan.onsets[j] + math.exp(plan.mu[j] - plan.sigma[j] ** 2 + spread)
            keep = (tau >= lo) & (tau <= hi)
            if keep.sum() < 2:
                continue
            y = length[j] * lognormal(tau[keep], plan.onsets[j], plan.mu[j], plan.sigma[j])
            curves.append(Curve(t[keep], y * speed_scale / scale))
    return curves


def _lifts(t: Array, pen: Array) -> list[tuple[float, float]]:
    up = np.concatenate([[0], (np.asarray(pen) == 0).astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(up))
    return [
        (float(t[max(a - 1, 0)]), float(t[min(b, len(t) - 1)]))
        for a, b in zip(edges[::2], edges[1::2], strict=True)
    ]


def speed_curves(
    tag: Tag, *, traces: Sequence[Any] | None = None, dt: float = 0.002
) -> SpeedCurves:
    """The speed plot of a tag, with the recorded speed of ``traces`` (one per plan, with
    timing) mapped onto the model's clock when given."""
    from tagbot.metrics import VELOCITY_CUTOFF

    motion = tag.sample(dt)
    speed = np.where(motion.pen == 1, motion.speed, np.nan)
    peak = float(np.max(motion.speed, initial=0.0))
    moving = (motion.pen == 0) & (motion.speed > AIR_SPEED * peak)
    air = Curve(motion.t, np.where(moving, motion.speed, np.nan)) if moving.any() else None
    measured = []
    if traces is not None:
        runs = list(motion.runs())
        for trace, (_, rows) in zip(traces, runs, strict=False):
            curve = recorded_speed(trace, motion.t[rows], motion.v[rows])
            if curve is not None:
                measured.append(curve)
    return SpeedCurves(
        speed=Curve(motion.t, speed),
        strokes=_stroke_curves(tag, motion.t),
        measured=measured,
        measured_label=f"recorded, {VELOCITY_CUTOFF:g} Hz low-pass (scaled and aligned)",
        lifts=_lifts(motion.t, motion.pen),
        units=tag.units,
        air=air,
    )


def recorded_speed(trace: Any, model_t: Array, model_v: Array) -> Curve | None:
    """A timed trace's speed on the model's clock (None without timing or too short): the
    reference the velocity SNR is measured against (low-passed at
    :data:`tagbot.metrics.VELOCITY_CUTOFF`), by the time scale and offset that best match the
    model's velocity
    (:func:`tagbot.metrics.velocity_snr`), or unmapped when the model shares the recording's
    clock and matches better so (a fit with ``timing="match"``)."""
    from tagbot.metrics import (
        VELOCITY_CUTOFF,
        clock_velocity_snr,
        recorded_velocity,
        velocity_snr,
    )

    t = getattr(trace, "t", None)
    if t is None:
        return None
    xy = np.asarray(trace.xy, dtype=float)
    try:
        best, scale, offset = velocity_snr(t, xy, model_t, model_v)
        grid, v = recorded_velocity(t, xy, cutoff=VELOCITY_CUTOFF)
        if clock_velocity_snr(t, xy, model_t, model_v) >= best:
            scale, offset = 1.0, float(model_t[0])
    except ValueError:
        return None
    return Curve(model_t[0] + (grid - offset) / scale, np.hypot(v[:, 0], v[:, 1]) * scale)


def executed_speed(t: Array, xy: Array, window: float = EXECUTED_WINDOW) -> Curve | None:
    """Speed of executed samples by central differences over ``max(window, 2 × median
    interval)`` seconds (None when the samples span less than that)."""
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, xy = t[keep], xy[keep]
    if len(t) < 2:
        return None
    width = max(window, 2.0 * float(np.median(np.diff(t))))
    if t[-1] - t[0] <= width:
        return None
    grid = np.arange(t[0] + width / 2, t[-1] - width / 2 + 1e-12, width / 2)
    ahead = np.column_stack([np.interp(grid + width / 2, t, xy[:, i]) for i in (0, 1)])
    behind = np.column_stack([np.interp(grid - width / 2, t, xy[:, i]) for i in (0, 1)])
    d = ahead - behind
    return Curve(grid, np.hypot(d[:, 0], d[:, 1]) / width)


# --------------------------------------------------------------------------- run folders


@dataclass(frozen=True, eq=False)
class Executed:
    """``executed.csv``: what the machine did, on the device's clock."""

    t: Array
    xy: Array
    pen: NDArray[np.int8]


@dataclass(frozen=True, eq=False)
class RunFolder:
    """The files of a ``tagbot draw`` run folder (None where a file is absent)."""

    path: Path
    tag: Tag | None
    motion: Any | None
    """``motion.csv`` as a :class:`tagbot.io.motionfile.MotionTable`."""
    executed: Executed | None
    mm_per_unit: float | None
    time_scale: float | None
    runs: list[dict[str, float]]
    timing: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    """Per plan: ``(scale, tag_start, start)`` from ``placement.runs``."""


def _read_executed(path: Path) -> Executed:
    header = "t,x,y,pen"
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read ({getattr(e, 'strerror', None) or e})") from e
    lines = text.splitlines()
    if not lines or lines[0].strip() != header:
        got = repr(lines[0][:40]) if lines else "an empty file"
        raise InputError(f"{path}:1: expected header {header!r}, got {got}")
    rows = [line for line in lines[1:] if line.strip()]
    if not rows:
        raise InputError(f"{path}: no samples")
    if any(row.count(",") != 3 for row in rows):
        raise InputError(f"{path}: expected 4 fields per line (t,x,y,pen)")
    try:  # one conversion of every field, in C
        data = np.array(",".join(rows).split(","), dtype=float).reshape(-1, 4)
    except ValueError as e:
        raise InputError(f"{path}: not numbers ({e})") from None
    if not np.all(np.isfinite(data)):
        raise InputError(f"{path}: values must be finite")
    return Executed(t=data[:, 0], xy=data[:, 1:3], pen=(data[:, 3] != 0).astype(np.int8))


RunTiming = dict[int, tuple[float, float, float]]
"""Per plan ``(scale, tag_start, start)``: machine time is ``start + scale * (tau - tag_start)``."""
Runs = list[dict[str, float]]


def _read_report(path: Path) -> tuple[float | None, float | None, Runs, RunTiming]:
    try:
        report = json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"{path}: cannot read as JSON ({e})") from None
    if not isinstance(report, dict):
        raise InputError(f"{path}: expected a JSON object")
    placement = report.get("placement") or {}
    values = []
    for key in ("mm_per_unit", "time_scale"):
        value = placement.get(key) if isinstance(placement, dict) else None
        if value is not None and not (
            isinstance(value, int | float) and math.isfinite(value) and value > 0
        ):
            raise InputError(f"{path}: placement.{key}: must be a positive number, got {value!r}")
        values.append(float(value) if value is not None else None)
    runs = []
    for k, run in enumerate(report.get("runs") or []):
        try:
            runs.append(
                {
                    "plan": int(run["plan"]),
                    "planned_start": float(run["planned_start"]),
                    "executed_start": float(run["executed_start"]),
                }
            )
        except (KeyError, TypeError, ValueError):
            raise InputError(
                f"{path}: runs[{k}]: expected plan, planned_start and executed_start"
            ) from None
    timing: RunTiming = {}
    entries = placement.get("runs") if isinstance(placement, dict) else None
    for k, entry in enumerate(entries or []):
        try:
            values_k = tuple(float(entry[key]) for key in ("scale", "tag_start", "start"))
            plan = int(entry["plan"])
        except (KeyError, TypeError, ValueError):
            raise InputError(
                f"{path}: placement.runs[{k}]: expected plan, scale, tag_start and start"
            ) from None
        if not all(math.isfinite(v) for v in values_k) or values_k[0] <= 0:
            raise InputError(f"{path}: placement.runs[{k}]: scale must be > 0, times finite")
        timing[plan] = values_k  # type: ignore[assignment]
    return values[0], values[1], runs, timing


def load_run(run_dir: str | os.PathLike[str]) -> RunFolder:
    """Read a run folder; InputError when it holds neither plan.json nor motion.csv."""
    from tagbot.io.motionfile import read_motion_csv
    from tagbot.io.planfile import load_plan

    folder = Path(run_dir)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a run folder (not a directory)")
    tag = load_plan(folder / "plan.json") if (folder / "plan.json").is_file() else None
    motion = read_motion_csv(folder / "motion.csv") if (folder / "motion.csv").is_file() else None
    if tag is None and motion is None:
        raise InputError(f"{folder}: not a run folder (no plan.json or motion.csv)")
    executed = (
        _read_executed(folder / "executed.csv") if (folder / "executed.csv").is_file() else None
    )
    mm_per_unit = time_scale = None
    runs: list[dict[str, float]] = []
    timing: dict[int, tuple[float, float, float]] = {}
    if (folder / "report.json").is_file():
        mm_per_unit, time_scale, runs, timing = _read_report(folder / "report.json")
    return RunFolder(folder, tag, motion, executed, mm_per_unit, time_scale, runs, timing)


def run_speed_curves(run: RunFolder) -> SpeedCurves:
    """Planned speed (motion.csv), the strokes' lognormals (plan.json, in machine units) and the
    executed speed (executed.csv, aligned per run) of a run folder."""
    if run.motion is None:
        if run.tag is None:  # pragma: no cover - load_run refuses this
            raise InputError(f"{run.path}: no motion.csv")
        return speed_curves(run.tag)
    motion = run.motion
    pen = np.asarray(motion.pen)
    t = np.asarray(motion.t, dtype=float)
    speed = np.where(pen == 1, np.asarray(motion.speed, dtype=float), np.nan)
    down = np.concatenate([[0], (pen == 1).astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(down))
    planned_starts = [float(t[a]) for a in edges[::2]]
    strokes: list[Curve] = []
    plans = range(len(run.tag.plans)) if run.tag is not None else range(0)
    if run.tag is not None and run.mm_per_unit and all(p in run.timing for p in plans):
        scales = [run.timing[p][0] for p in plans]
        offsets = [run.timing[p][2] - run.timing[p][0] * run.timing[p][1] for p in plans]
        strokes = _stroke_curves(run.tag, t, offsets, scales, run.mm_per_unit)
    elif run.tag is not None and run.time_scale and run.mm_per_unit:
        starts = {int(r["plan"]): float(r["planned_start"]) for r in run.runs}
        offsets = []
        for p, plan in enumerate(run.tag.plans):
            start = starts.get(p, planned_starts[p] if p < len(planned_starts) else None)
            if start is None:
                break
            offsets.append(start - run.time_scale * plan.start)
        if len(offsets) == len(run.tag.plans):
            strokes = _stroke_curves(run.tag, t, offsets, run.time_scale, run.mm_per_unit)
    measured = []
    if run.executed is not None and run.runs:
        from tagbot.metrics import executed_runs

        ex = run.executed
        table = np.column_stack([ex.t, ex.xy, ex.pen])
        # Pen-down runs matched in order, as tagbot.metrics.compare_execution matches them.
        for r, executed in zip(run.runs, executed_runs(table), strict=False):
            curve = executed_speed(executed[:, 0], executed[:, 1:3])
            if curve is not None:
                shift = r["planned_start"] - r["executed_start"]
                measured.append(Curve(curve.t + shift, curve.y))
    return SpeedCurves(
        speed=Curve(t, speed),
        strokes=strokes,
        measured=measured,
        measured_label="executed",
        lifts=_lifts(t, pen),
        units="mm",
        speed_label="planned speed |v|",
    )


# --------------------------------------------------------------------------- figures


def _figure(width: float = 9.0, height: float = 4.0) -> Figure:
    figure = Figure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def speed_figure(curves: SpeedCurves, *, title: str | None = None) -> Figure:
    """Speed over time: total (red; dashed in the air), strokes' lognormals (turquoise),
    measured (orange, on top)."""
    figure = _figure()
    ax = figure.add_subplot()
    for k, (a, b) in enumerate(curves.lifts):
        ax.axvspan(
            a,
            b,
            color=LIFT_COLOR,
            alpha=LIFT_ALPHA,
            linewidth=0,
            label="pen up (lifted between runs)" if k == 0 else None,
        )
    if curves.strokes:
        ax.add_collection(
            LineCollection(
                [np.column_stack([c.t, c.y]) for c in curves.strokes],
                colors=STROKE_COLOR,
                linewidths=1.0,
                label="strokes  $D_j\\,\\Lambda(t; t_{0j}, \\mu_j, \\sigma_j)$",
            )
        )
        for c in curves.strokes:
            ax.fill_between(c.t, c.y, color=STROKE_COLOR, alpha=0.12, linewidth=0)
    ax.plot(
        curves.speed.t, curves.speed.y, color=SPEED_COLOR, linewidth=2.2, label=curves.speed_label
    )
    if curves.air is not None:
        ax.plot(
            curves.air.t,
            curves.air.y,
            color=SPEED_COLOR,
            linewidth=1.4,
            linestyle=(0, (3, 2)),
            label="in the air (pen up, moving)",
        )
    for k, c in enumerate(curves.measured):  # on top, thinner: visible even where they agree
        ax.plot(
            c.t,
            c.y,
            color=MEASURED_COLOR,
            linewidth=1.1,
            label=curves.measured_label if k == 0 else None,
        )
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"speed ({curves.units}/s)")
    ax.set_ylim(bottom=0)
    finite = curves.speed.t[np.isfinite(curves.speed.y)]
    if len(finite):
        ax.set_xlim(float(curves.speed.t[0]), float(curves.speed.t[-1]))
    ax.grid(True, alpha=0.25)
    if title:
        ax.set_title(title)
    # Outside the axes, above them: a legend never covers a curve (two rows past four entries).
    entries = len(ax.get_legend_handles_labels()[0])
    columns = entries if entries <= 4 else (entries + 1) // 2
    figure.legend(loc="outside upper center", ncols=columns, fontsize="small", frameon=False)
    return figure


def plan_figure(
    tag: Tag, *, traces: Sequence[Any] | None = None, title: str | None = None, dt: float = 0.002
) -> Figure:
    """The action plan over the trajectory (see the module docstring for the glyphs)."""
    points = np.concatenate([p.targets for p in tag.plans])
    extent = np.ptp(points, axis=0)
    aspect = float(extent[1] / extent[0]) if extent[0] > 0 else 1.0
    width = 9.0
    figure = _figure(width, float(np.clip(width * aspect, 3.0, 12.0)))
    ax = figure.add_subplot()
    size = tag.size
    if traces is not None:
        for k, trace in enumerate(traces):
            xy = np.asarray(getattr(trace, "xy", trace), dtype=float)
            ax.plot(
                xy[:, 0],
                xy[:, 1],
                color=TRACE_COLOR,
                linewidth=3.0,
                alpha=0.7,
                label="input trace" if k == 0 else None,
                solid_capstyle="round",
            )
    motion = tag.sample(dt)
    for k, (_, rows) in enumerate(motion.runs()):
        ax.plot(
            motion.xy[rows, 0],
            motion.xy[rows, 1],
            color="black",
            linewidth=1.4,
            label="trajectory" if k == 0 else None,
        )
    handles: list[Array] = []
    dt_handles: list[Array] = []
    labels: list[tuple[Array, str]] = []
    dt_max = max(float(np.max(p.dt)) for p in tag.plans) or 1.0
    for plan in tag.plans:
        targets = plan.targets
        ax.plot(targets[:, 0], targets[:, 1], linestyle=":", color=TARGET_COLOR, linewidth=1.2)
        chord = plan.chords
        c = np.hypot(chord[:, 0], chord[:, 1])
        alpha = np.arctan2(chord[:, 1], chord[:, 0])
        reach = np.minimum(0.3 * c, 0.08 * size)
        start = alpha + plan.phi1
        end = alpha + plan.phi2
        a = targets[:-1]
        tip = a + reach[:, None] * np.column_stack([np.cos(start), np.sin(start)])
        handles += [np.stack([p, q]) for p, q in zip(a, tip, strict=True)]
        if tag.model == "gamma":
            b = targets[1:]
            back = b - reach[:, None] * np.column_stack([np.cos(end), np.sin(end)])
            handles += [np.stack([p, q]) for p, q in zip(b, back, strict=True)]
        # Δt handles: perpendicular to the chord, to its right, length ∝ dt.
        normal = np.column_stack([np.sin(alpha), -np.cos(alpha)])
        length = 0.08 * size * plan.dt / dt_max
        ends = a + length[:, None] * normal
        for j in range(plan.n_strokes):
            if plan.dt[j] > 0:
                dt_handles.append(np.stack([a[j], ends[j]]))
                labels.append((ends[j], f"{1000 * plan.dt[j]:.0f} ms"))
    if handles:
        ax.add_collection(
            LineCollection(
                handles, colors=STROKE_COLOR, linewidths=1.6, label="tangent handles ($\\phi$)"
            )
        )
        tips = np.array([h[1] for h in handles])
        ax.plot(tips[:, 0], tips[:, 1], "o", color=STROKE_COLOR, markersize=3.5)
    if dt_handles:
        ax.add_collection(
            LineCollection(dt_handles, colors=DT_COLOR, linewidths=1.6, label="$\\Delta t$ handles")
        )
        ends = np.array([h[1] for h in dt_handles])
        ax.plot(ends[:, 0], ends[:, 1], "^", color=DT_COLOR, markersize=5)
        dt_labels = [
            ax.annotate(
                text, where, textcoords="offset points", xytext=(3, -3), fontsize=6, color=DT_COLOR
            )
            for where, text in labels
        ]
    else:
        dt_labels = []
    ax.plot(
        points[:, 0], points[:, 1], "s", color=TARGET_COLOR, markersize=5, label="virtual targets"
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.2)
    ax.set_xlabel(f"x ({tag.units})")
    ax.set_ylabel(f"y ({tag.units})")
    figure.legend(loc="outside lower center", ncols=5, fontsize="small", frameon=False)
    model = "ΓΛ*" if tag.model == "gamma" else "ΣΛ*"
    ax.set_title(title or f"{model} action plan: {len(tag.plans)} plans, {tag.n_strokes} strokes")
    _thin_labels(figure, dt_labels)
    return figure


def _thin_labels(figure: Figure, texts: Sequence[Any], pad: float = 2.0) -> None:
    """Hide the labels that would overlap one shown before them (in order), so that no two
    shown overlap: their boxes on the laid-out figure, grown by ``pad`` pixels."""
    if len(texts) < 2:
        return
    figure.draw_without_rendering()  # lays the figure out, so the boxes are final
    renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
    extents = np.array([t.get_window_extent(renderer).extents for t in texts])
    boxes = extents + np.array([-pad, -pad, pad, pad])
    kept = np.empty_like(boxes)
    count = 0
    for text, box in zip(texts, boxes, strict=True):
        shown = kept[:count]
        hit = (
            (shown[:, 0] < box[2])
            & (box[0] < shown[:, 2])
            & (shown[:, 1] < box[3])
            & (box[1] < shown[:, 3])
        )
        if hit.any():
            text.set_visible(False)
        else:
            kept[count] = box
            count += 1


def plot_format(path: str | os.PathLike[str]) -> str:
    """The plot format told by the suffix of ``path``: png, svg or pdf."""
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in ("png", "svg", "pdf"):
        raise RenderError(f"{os.fspath(path)}: a plot is a .png, .svg or .pdf")
    return suffix


def save_figure(figure: Figure, path: str | os.PathLike[str]) -> None:
    """Save a figure (format from the suffix: png, svg or pdf)."""
    figure.savefig(path, format=plot_format(path))


def plot(
    source: Tag | RunFolder | str | os.PathLike[str],
    path: str | os.PathLike[str],
    *,
    kind: str = "speed",
    traces: Sequence[Any] | None = None,
) -> Path:
    """Write a speed or action-plan plot of a tag (with its input ``traces`` when fitted) or of a
    run folder."""
    if kind not in PLOT_KINDS:
        raise RenderError(f"kind: must be one of {', '.join(PLOT_KINDS)}, got {kind!r}")
    plot_format(path)
    if isinstance(source, str | os.PathLike):
        source = load_run(source)
    if isinstance(source, RunFolder):
        if kind == "speed":
            figure = speed_figure(run_speed_curves(source), title="planned and executed speed")
        elif source.tag is None:
            raise InputError(f"{source.path}: no plan.json to plot the action plan from")
        else:
            figure = plan_figure(source.tag)
    elif kind == "speed":
        figure = speed_figure(speed_curves(source, traces=traces))
    else:
        figure = plan_figure(source, traces=traces)
    save_figure(figure, path)
    return Path(path)


def executed_motion(
    executed: Executed, window: float = EXECUTED_WINDOW, spacing: float = 0.0
) -> MotionLike:
    """``executed.csv`` as a motion to paint: each pen-down run's positions smoothed by a moving
    average over ``window`` seconds (a recorder's steps and jitter are not the pen's path),
    velocities by central differences, and then only the samples that move at least ``spacing``
    (tag units) or ``window`` seconds on from the previous one kept (a 1 ms record of a slow
    machine holds far more samples than the brush needs)."""
    from scipy.ndimage import uniform_filter1d

    from tagbot.io.motionfile import MotionTable

    t, xy, pen = executed.t, executed.xy.copy(), executed.pen
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, xy, pen = t[keep], xy[keep], pen[keep]
    down = np.concatenate([[0], (pen != 0).astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(down))
    v = np.zeros_like(xy)
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a < 2:
            continue
        step = float(np.median(np.diff(t[a:b])))
        span = max(1, round(window / step)) if step > 0 else 1
        xy[a:b] = uniform_filter1d(xy[a:b], size=span, axis=0, mode="nearest")
        v[a:b] = np.gradient(xy[a:b], t[a:b], axis=0)
    if spacing > 0 and len(t) > 2:
        step = np.concatenate([[0.0], np.hypot(*np.diff(xy, axis=0).T)])
        # Both counts only grow, so their sum changes exactly when one of them does.
        key = np.floor(np.cumsum(step) / spacing) + np.floor((t - t[0]) / window)
        pen_change = np.concatenate([[True], np.diff(pen) != 0])
        pen_change |= np.concatenate([np.diff(pen) != 0, [True]])
        keep = pen_change | np.concatenate([[True], np.diff(key) != 0])
        t, xy, v, pen = t[keep], xy[keep], v[keep], pen[keep]
    return MotionTable(t=t, xy=xy, v=v, speed=np.hypot(v[:, 0], v[:, 1]), pen=pen)


PLANNED_ONLY = "#1f6fd1"
EXECUTED_ONLY = "#d62728"


def exaggerated(
    planned: Sequence[Array], executed: Sequence[Array], target: float
) -> tuple[list[Array], float]:
    """The executed runs' points moved away from the planned path ``k`` times their deviation
    (the distance to the nearest point of the planned runs, densified to 1/200,000 of their
    length; deviations under that spacing count as none), ``k`` in [1, 1000] chosen so the
    largest deviation shows as ``target``."""
    from scipy.spatial import cKDTree

    lengths = [float(np.hypot(*np.diff(r, axis=0).T).sum()) for r in planned if len(r) > 1]
    spacing = max(sum(lengths), 1e-12) / 200_000
    dense = []
    for run in planned:
        if len(run) < 2:
            dense.append(run)
            continue
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(run, axis=0).T))])
        grid = np.linspace(0.0, s[-1], max(2, int(s[-1] / spacing) + 2))
        dense.append(np.column_stack([np.interp(grid, s, run[:, i]) for i in (0, 1)]))
    tree = cKDTree(np.concatenate(dense))
    found = [tree.query(run) for run in executed]
    largest = max((float(d.max()) for d, _ in found if len(d)), default=0.0)
    exact = largest <= spacing  # within the densified path's own resolution
    k = 1.0 if exact else float(np.clip(target / largest, 1.0, 1000.0))
    points = tree.data
    moved = [points[i] + k * (run - points[i]) for run, (_, i) in zip(executed, found, strict=True)]
    return moved, k


def execution_figure(
    planned: NDArray[np.floating],
    executed: NDArray[np.floating],
    view: Any,
    *,
    paths: tuple[Sequence[Array], Sequence[Array]] | None = None,
    target: float | None = None,
    title: str = "planned and executed ink",
) -> Figure:
    """The planned and executed ink opacities ``(height, width)`` of one view overlaid: ink only
    in the plan blue, only in the execution red, in both black; axes in machine mm. With
    ``paths`` (planned and executed pen-down runs, ``(N, 2)`` each), a second panel shows the
    executed paths with their deviation from the plan exaggerated (:func:`exaggerated`, the
    largest shown as ``target`` mm, default a fiftieth of the view)."""
    p = np.clip(np.asarray(planned, dtype=np.float32), 0.0, 1.0)[..., None]
    e = np.clip(np.asarray(executed, dtype=np.float32), 0.0, 1.0)[..., None]
    blue = np.array([int(PLANNED_ONLY[i : i + 2], 16) / 255 for i in (1, 3, 5)], dtype=np.float32)
    red = np.array([int(EXECUTED_ONLY[i : i + 2], 16) / 255 for i in (1, 3, 5)], dtype=np.float32)
    both = np.float32(0.07)
    only_p, only_e, shared = p * (1 - e), e * (1 - p), p * e
    rgb = (1 - only_p - only_e - shared) + only_p * blue + only_e * red + shared * both
    aspect = view.height / view.width
    panels = 1 if paths is None else 2
    width = 7.0 * panels
    figure = _figure(width, float(np.clip(7.0 * aspect + 1.2, 3.0, 12.0)))
    axes = figure.subplots(1, panels, squeeze=False)[0]
    ax = axes[0]
    extent = (view.xmin, view.xmax, view.ymin, view.ymax)
    ax.imshow(np.clip(rgb, 0.0, 1.0), extent=extent, interpolation="antialiased")
    from matplotlib.patches import Patch

    handles = [
        Patch(color=PLANNED_ONLY, label="planned only"),
        Patch(color=EXECUTED_ONLY, label="executed only"),
        Patch(color="#121212", label="both"),
    ]
    ax.set_title(title)
    if paths is not None:
        target = target if target is not None else 0.02 * max(view.xmax - view.xmin, 1e-12)
        moved, k = exaggerated(paths[0], paths[1], target)
        path_ax = axes[1]
        for j, run in enumerate(paths[0]):
            path_ax.plot(
                run[:, 0],
                run[:, 1],
                color=PLANNED_ONLY,
                linewidth=0.9,
                label="planned path" if j == 0 else None,
            )
        for j, run in enumerate(moved):
            path_ax.plot(
                run[:, 0],
                run[:, 1],
                color=EXECUTED_ONLY,
                linewidth=0.9,
                label=f"executed path, deviation x{k:.3g}" if j == 0 else None,
            )
        path_ax.set_xlim(view.xmin, view.xmax)
        path_ax.set_ylim(view.ymin, view.ymax)
        path_ax.set_aspect("equal")
        path_ax.set_title(f"path deviation, exaggerated x{k:.3g}")
        handles += path_ax.get_legend_handles_labels()[0]
    for a in axes:
        a.set_xlabel("x (mm)")
        a.set_ylabel("y (mm)")
    figure.legend(
        handles=handles, loc="outside lower center", ncols=5, fontsize="small", frameon=False
    )
    return figure


def _down_runs(motion: Any) -> list[Array]:
    """The pen-down runs' positions of a motion (or a sampled tag)."""
    if isinstance(motion, Tag):
        motion = motion.sample(0.002)
    pen = np.asarray(motion.pen) != 0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], pen.astype(np.int8), [0]])))
    xy = np.asarray(motion.xy, dtype=float)
    return [xy[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True)]


def pictures_for_run(
    run_dir: str | os.PathLike[str], *, size: int = 800, seed: int = 1
) -> list[Path]:
    """Write the pictures of a run folder and return the paths written:

    - ``tag.png``: the plan's ink (``motion.csv`` in machine mm, else ``plan.json``), with drips
      (``seed``);
    - ``executed.png``: what the machine drew (``executed.csv``, :func:`executed_motion`), with the
      same brush, seed and window as ``tag.png``, and ``execution.png``, both overlaid beside
      the paths with the deviation exaggerated (:func:`execution_figure`), when the folder has
      an ``motion.csv`` and an ``executed.csv``;
    - ``speed.png``: planned and executed speed with the strokes' lognormals;
    - ``plan.png``: the action plan, when there is a ``plan.json``.
    """
    from tagbot.render.api import prepare
    from tagbot.render.raster import compose, coverage, make_view, write_png

    run = load_run(run_dir)
    written = []
    source = run.motion if run.motion is not None else run.tag
    planned = prepare(source, drips=True, seed=seed)
    executed = None
    if run.executed is not None and run.motion is not None and np.any(run.executed.pen):
        spacing = planned.brush.nib * planned.size / 8.0
        executed_source = executed_motion(run.executed, spacing=spacing)
        executed = prepare(executed_source, drips=True, seed=seed, brush=planned.brush)
    bounds = np.array(planned.bounds())
    if executed is not None:
        other = np.array(executed.bounds())
        bounds = np.concatenate(
            [np.minimum(bounds[:2], other[:2]), np.maximum(bounds[2:], other[2:])]
        )
    view = make_view(tuple(bounds.tolist()), size=size, units=planned.units)  # type: ignore[arg-type]
    alpha = coverage(planned, view)
    write_png(compose(alpha), run.path / "tag.png", view.dpi)
    written.append(run.path / "tag.png")
    if executed is not None:
        drawn = coverage(executed, view)
        write_png(compose(drawn), run.path / "executed.png", view.dpi)
        paths = (_down_runs(source), _down_runs(executed_source))
        figure = execution_figure(alpha, drawn, view, paths=paths)
        save_figure(figure, run.path / "execution.png")
        written += [run.path / "executed.png", run.path / "execution.png"]
    speed_png = run.path / "speed.png"
    save_figure(speed_figure(run_speed_curves(run), title="planned and executed speed"), speed_png)
    written.append(speed_png)
    if run.tag is not None:
        plan_png = run.path / "plan.png"
        save_figure(plan_figure(run.tag), plan_png)
        written.append(plan_png)
    return written
