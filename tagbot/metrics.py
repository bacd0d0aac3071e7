"""How well a reconstruction matches its input: shape error, stroke counts, velocity SNR.

Shared by ``tagbot fit``, the benchmarks and the machine reports.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from tagbot.model.motion import Motion
from tagbot.model.plan import Tag

Array = NDArray[np.float64]

DENSITY = 4000
"""Polylines are densified to at least this many points per bounding-box diagonal."""


@dataclass(frozen=True)
class ShapeError:
    """Closest-point distances between two sets of polylines, as fractions of the input's size."""

    mean: float
    """Mean over both directions (input → reconstruction and back)."""
    max: float
    """The largest distance either way (Hausdorff distance)."""
    size: float
    """The input's bounding-box diagonal the figures are divided by."""


def densify(polyline: ArrayLike, spacing: float) -> Array:
    """The polyline with points inserted so consecutive points are at most ``spacing`` apart."""
    xy = np.asarray(polyline, dtype=float)
    if len(xy) < 2:
        return xy
    seg = np.hypot(*np.diff(xy, axis=0).T)
    pieces = np.maximum(1, np.ceil(seg / spacing).astype(np.intp))
    start = np.repeat(xy[:-1], pieces, axis=0)
    delta = np.repeat(np.diff(xy, axis=0) / pieces[:, None], pieces, axis=0)
    offset = np.arange(int(pieces.sum())) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    return np.vstack([start + delta * offset[:, None], xy[-1:]])


def shape_error(reference: Sequence[ArrayLike], candidate: Sequence[ArrayLike]) -> ShapeError:
    """Mean and max closest-point distance between two drawings, over the reference's size.

    Both are lists of polylines ``(N, 2)``; each is densified to :data:`DENSITY` points per
    diagonal, so distances are exact to within 1/(2·DENSITY) of the size.
    """
    ref = [np.asarray(p, dtype=float) for p in reference if len(p)]
    cand = [np.asarray(p, dtype=float) for p in candidate if len(p)]
    if not ref or not cand:
        raise ValueError("shape_error: both drawings need at least one point")
    points = np.concatenate(ref)
    size = float(np.hypot(*np.ptp(points, axis=0))) or 1.0
    spacing = size / DENSITY
    a = np.concatenate([densify(p, spacing) for p in ref])
    b = np.concatenate([densify(p, spacing) for p in cand])
    a_to_b, _ = cKDTree(b).query(a)
    b_to_a, _ = cKDTree(a).query(b)
    mean = (a_to_b.sum() + b_to_a.sum()) / (len(a) + len(b))
    return ShapeError(
        mean=float(mean) / size, max=float(max(a_to_b.max(), b_to_a.max())) / size, size=size
    )


def pen_down_paths(motion: Motion) -> list[Array]:
    """The motion's pen-down runs as polylines."""
    return [np.asarray(motion.xy[rows]) for _, rows in motion.runs()]


def turning_of(polylines: Sequence[ArrayLike]) -> float:
    """Total absolute turning of polylines, in half turns (180°)."""
    total = 0.0
    for p in polylines:
        d = np.diff(np.asarray(p, dtype=float), axis=0)
        d = d[np.hypot(*d.T) > 0]
        if len(d) < 2:
            continue
        cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
        dot = np.einsum("ij,ij->i", d[:-1], d[1:])
        total += float(np.sum(np.abs(np.arctan2(cross, dot))))
    return total / np.pi


def velocity_snr(
    t: ArrayLike, xy: ArrayLike, model_t: ArrayLike, model_v: ArrayLike, dt: float = 0.01
) -> tuple[float, float, float]:
    """SNR in dB of a model velocity against a recorded trajectory, after the best time mapping.

    The recording (times ``t``, points ``xy``) is resampled every ``dt`` seconds and its velocity
    taken by central differences; the model velocity ``model_v`` (at ``model_t``) is mapped to the
    recording's clock by ``t = offset + scale·(t_model − model_t[0])`` (velocities divide by
    ``scale``). Returns
    ``(snr_db, scale, offset)`` for the scale and offset maximising
    ``10·log10(Σ|v|² / Σ|v − v̂|²)``.
    """
    model_t, model_v = np.asarray(model_t, dtype=float), np.asarray(model_v, dtype=float)
    model_t = model_t - model_t[0]  # the mapping's offset is from the model's first sample
    if len(model_t) < 2:
        raise ValueError("velocity_snr: the model needs at least 2 samples")
    grid, v = recorded_velocity(t, xy, dt)
    energy = float(np.sum(v * v))
    model_span = model_t[-1] - model_t[0]

    def snr(scale: float, offset: float) -> float:
        tm = (grid - offset) / scale
        vm = np.column_stack(
            [np.interp(tm, model_t, model_v[:, i], left=0.0, right=0.0) for i in (0, 1)]
        )
        err = v - vm / scale
        return 10.0 * np.log10(energy / max(float(np.sum(err * err)), 1e-300))

    best = (-np.inf, 1.0, 0.0)
    span = grid[-1] - grid[0]
    for scale in np.geomspace(0.25, 4.0, 41) * (span / model_span if model_span > 0 else 1.0):
        slack = span - scale * model_span
        for offset in grid[0] + np.linspace(min(0.0, slack), max(0.0, slack), 21):
            value = snr(scale, offset)
            if value > best[0]:
                best = (value, scale, offset)
    # Refine around the best coarse pair.
    _, scale, offset = best
    for width in (0.1, 0.02, 0.004):
        for s in scale * np.linspace(1 - width, 1 + width, 9):
            for o in offset + span * np.linspace(-width, width, 9):
                value = snr(s, o)
                if value > best[0]:
                    best = (value, s, o)
        _, scale, offset = best
    return best


@dataclass(frozen=True)
class FitReport:
    """How a tag reconstructed from traces compares with them."""

    traces: int
    points: int
    strokes: int
    shape: ShapeError
    strokes_per_half_turn: float
    """Strokes per 180° of the input's turning (the paper adds one per 180°)."""
    velocity_snr_db: float | None
    """Velocity SNR against the recorded timing (None when the input has none)."""

    def summary(self) -> str:
        """One line for people."""
        snr = (
            f", velocity SNR {self.velocity_snr_db:.1f} dB"
            if self.velocity_snr_db is not None
            else ""
        )
        return (
            f"{_count(self.traces, 'trace')} ({_count(self.points, 'point')}) ->"
            f" {_count(self.strokes, 'stroke')}; shape error mean {100 * self.shape.mean:.2f}%"
            f" max {100 * self.shape.max:.2f}% of {self.shape.size:.4g}{snr}"
        )


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'s' * (n != 1)}"


def fit_report(traces: Sequence[object], tag: Tag, dt: float = 0.005) -> FitReport:
    """Compare a reconstructed ``tag`` (one plan per trace) with its input ``traces``.

    Traces are objects with ``xy`` and optional ``t`` (as :func:`tagbot.load_traces` returns).
    """
    polylines = [np.asarray(getattr(tr, "xy", tr), dtype=float) for tr in traces]
    motion = tag.sample(dt)
    shape = shape_error(polylines, pen_down_paths(motion))
    turning = turning_of(polylines)
    snr = None
    timed = [tr for tr in traces if getattr(tr, "t", None) is not None]
    if timed and len(timed) == len(traces) == len(tag.plans):
        signal = noise = 0.0
        for trace, (_, rows) in zip(traces, motion.runs(), strict=True):
            t, xy = np.asarray(trace.t), np.asarray(trace.xy)
            try:
                db, _, _ = velocity_snr(t, xy, motion.t[rows], motion.v[rows])
            except ValueError:  # too short to compare
                continue
            _, v = recorded_velocity(t, xy)
            energy = float(np.sum(v * v))
            signal += energy
            noise += energy / 10 ** (db / 10)
        snr = 10 * np.log10(signal / noise) if noise > 0 else None
    return FitReport(
        traces=len(polylines),
        points=sum(len(p) for p in polylines),
        strokes=tag.n_strokes,
        shape=shape,
        strokes_per_half_turn=tag.n_strokes / turning if turning > 0 else float("nan"),
        velocity_snr_db=snr,
    )


def recorded_velocity(t: ArrayLike, xy: ArrayLike, dt: float = 0.01) -> tuple[Array, Array]:
    """A recording resampled every ``dt`` seconds and its velocity by central differences.

    Repeated time stamps are dropped (the first of each kept).
    """
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    keep = np.concatenate([[True], np.diff(t) > 0])
    t, xy = t[keep], xy[keep]
    if len(t) < 3 or t[-1] - t[0] < 3 * dt:
        raise ValueError("velocity: the recording needs at least 3 samples over 3·dt")
    grid = np.arange(t[0], t[-1], dt)
    rec = np.column_stack([np.interp(grid, t, xy[:, 0]), np.interp(grid, t, xy[:, 1])])
    return grid, np.gradient(rec, dt, axis=0)
