"""The AxiDraw (issue 31): tagbot's timed moves beside the AxiDraw software's, same simulated EBB.

Run from the repository root (``../shared/data`` adds the development GML tags when present)::

    python benchmarks/bench_axidraw.py [--gml 45] [--data ../shared/data] [--quick]
                                       [--tags NAME,...] [--profile default] [--csv axidraw.csv]

Every tag is placed on the AxiDraw V3 profile (``default``) and drawn twice on the in-process
simulated EBB (firmware 3.0.3, ``ebbsim://``, 1 ms recorder of its 40 µs ticks):

- **tagbot**: exactly as ``tagbot draw TAG --device axidraw`` does without ``--port``
  (:func:`tagbot.draw.draw`): one ``T3`` move per setpoint, the plan's speed. From its
  ``report.json``: the worst run's speed SNR against the plan (goal ≥ 35 dB) and the path
  deviation (goal ≤ 0.02 mm); the job time against a lower bound computed here (goal ≤ 1.1).
- **classic**: the same pen-down paths as the AxiDraw software (AxiDraw CLI / pyaxidraw,
  ``motion.py``) plans them with its defaults (:func:`classic_job`): each path a polyline,
  trapezoidal speed at a constant cruise speed (``speed_pendown`` 25 of 110 % of the profile's
  ``limits.draw_speed``, its 8.6979 in/s: 50.2 mm/s), the profile's pen-down acceleration (its
  30 in/s², 762 mm/s²), slowing at corners as its cornering rule does (``cornering`` 10), cut in
  25 ms slices of constant speed sent as ``SM`` moves; pen-up moves alike at ``speed_penup`` 75
  (150.7 mm/s, 1143 mm/s²). The same ``SP`` pen moves. Streamed by tagbot's own
  :class:`~tagbot.axidraw.stream.EBBStreamer` into a fresh simulated board.

Both executed traces are then held against the *writer's* speed profile, the plan's lognormal
motion at tagbot's placement and time scale (:func:`tagbot.metrics.compare_execution`, the same
comparison ``report.json`` makes): the speed SNR as drawn (each run aligned at its onset), the
same with each planned run stretched in time to the executed run's duration (the speed profile's
*shape*, whatever the pace), and the drawing time against the plan's.

The lower bound (:func:`lower_bound`, independent of tagbot's placement and moves): every run's
motion (the tag's, on the run's own clock) at the least time scale ``s ≥ 1`` that keeps the speed
and the acceleration along both motors within ``limits.draw_speed`` / ``draw_acceleration``
(sampled every 0.5 ms), each travel (home, between runs, park) as a rest-to-rest trapezoid
along the longer motor axis at ``limits.travel_speed`` / ``travel_acceleration``, and each pen
move's servo time. The job time compared with it is ``report.json``'s ``executed_duration_s``
(the first pen lift and the board's pace included).

The tags: the shipped examples (``tagbot/examples/*.json``) and ``--gml N`` development GML tags
(all 45 by default) evenly spaced in name order, fitted with ``tagbot.fit``. ``--quick``:
``letter-b`` and ``cae`` only (about a minute).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import serial

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_plotter import example_tags, gml_tags

import tagbot
from tagbot.axidraw.machine import prepare
from tagbot.axidraw.moves import steps_to_xy
from tagbot.axidraw.profile import MOTOR_AXES, Profile, load_profile
from tagbot.axidraw.stream import EBBStreamer
from tagbot.draw import draw
from tagbot.metrics import compare_execution, executed_runs

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"

SNR_GOAL = 35.0
DEVIATION_GOAL = 0.02
BOUND_GOAL = 1.1

INCH = 25.4
# The AxiDraw software's defaults (axidraw_conf.py): percentages of its fastest speed
# (speed_lim_xy_hr, the profile's limits.draw_speed) divided by 110, cornering, the time slice.
SPEED_PENDOWN = 25.0
SPEED_PENUP = 75.0
SPEED_DIVISOR = 110.0
CORNERING = 10.0
TIME_SLICE = 0.025
"""s: the constant-speed slices each segment is cut in."""
CRUISE_CHUNK = 20
"""Slices in one cruise move at most (a long cruise is sent as 0.5 s moves)."""
MIN_SEGMENT = 0.000348 * INCH
"""mm: segments shorter than one step's largest distance are skipped (max_step_dist_hr)."""
MAX_STEP_RATE = 24.995
"""Steps per ms: a move faster than this on a motor is lengthened by whole ms."""
SLOW_AXIS = 0.002
"""Steps per ms: an axis slower than this in a move is held still (its steps carried on)."""
POLYLINE_TOLERANCE = 0.01
"""mm: how far the polyline given to the classic planner may stray from the tag's path (the
path sampled every 1 ms of its run, then simplified: what an SVG export of the tag holds)."""
TRACE_TICKS = 25
"""Ticks between the executed trace's samples (1 ms)."""


def mark(ok: bool) -> str:
    return "✓" if ok else "✗"


# -- the classic planner (the AxiDraw software's trapezoids) ------------------------------------


@dataclass(frozen=True)
class Classic:
    """The classic planner's settings, mm and s."""

    speed: float
    """Cruise speed along the path, mm/s."""
    accel: float
    """mm/s²."""
    corner: float
    """The cornering rule's deviation δ, mm (``cornering / 5000`` in)."""
    slow: float
    """The constant speed for a segment starting and ending at rest, mm/s."""

    @classmethod
    def pen_down(cls, profile: Profile) -> Classic:
        top = profile["limits.draw_speed"]
        return cls(
            speed=SPEED_PENDOWN * top / SPEED_DIVISOR,
            accel=profile["limits.draw_acceleration"],
            corner=CORNERING / 5000.0 * INCH,
            slow=SPEED_PENDOWN * top / SPEED_DIVISOR / 10.0,
        )

    @classmethod
    def pen_up(cls, profile: Profile) -> Classic:
        down = cls.pen_down(profile)
        return cls(
            speed=SPEED_PENUP * profile["limits.draw_speed"] / SPEED_DIVISOR,
            accel=profile["limits.travel_acceleration"],
            corner=down.corner,
            slow=down.slow,
        )


def junction_speed(before: np.ndarray, after: np.ndarray, accel: float, corner: float) -> float:
    """The fastest speed through a vertex between unit directions ``before`` and ``after``: the
    corner rounded by a circle whose nearest point is ``corner`` mm from the vertex, taken at
    ``accel`` centripetal acceleration (the cornering rule of Grbl's planner that the AxiDraw
    software uses)."""
    # sin(θ/2), θ the angle at the vertex between the path behind and the path ahead: 1 going
    # straight on (no circle is needed), 0 turning back (the circle shrinks to the vertex).
    half = math.sqrt(max(0.0, (1.0 + float(np.dot(before, after))) / 2.0))
    if 1.0 - half <= 1e-4:
        return math.inf
    radius = corner * half / (1.0 - half)
    return math.sqrt(accel * radius)


def vertex_speeds(points: np.ndarray, rule: Classic) -> tuple[np.ndarray, np.ndarray]:
    """The polyline with its too-short segments dropped, and the speed at each of its vertices:
    0 at both ends; forward, what the acceleration allows from the previous vertex, capped by
    the cruise speed and the corner; backward, what still lets it slow to the next."""
    kept = [points[0]]
    for p in points[1:]:
        if math.dist(p, kept[-1]) >= MIN_SEGMENT:
            kept.append(p)
    path = np.asarray(kept, dtype=float)
    n = len(path)
    speeds = np.zeros(n)
    if n < 3:
        return path, speeds
    d = np.diff(path, axis=0)
    lengths = np.hypot(d[:, 0], d[:, 1])
    units = d / lengths[:, None]
    reach = rule.speed**2 / (2.0 * rule.accel)  # distance from rest to cruise
    for i in range(1, n - 1):
        if lengths[i - 1] > reach:
            top = rule.speed
        else:
            top = min(rule.speed, math.sqrt(speeds[i - 1] ** 2 + 2.0 * rule.accel * lengths[i - 1]))
        speeds[i] = min(top, junction_speed(units[i - 1], units[i], rule.accel, rule.corner))
    for i in range(n - 1, 0, -1):
        if speeds[i - 1] > speeds[i]:
            speeds[i - 1] = min(
                speeds[i - 1], math.sqrt(speeds[i] ** 2 + 2.0 * rule.accel * lengths[i - 1])
            )
    return path, speeds


def _ramp(
    v_from: float, v_to: float, span: float, slices: int, start: float | None = None
) -> list[tuple[float, float]]:
    """``slices`` equal slices over ``span`` s, in steps of ``(v_to - v_from) / (slices + 1)``
    from ``start`` (default ``v_from``): the first one step past it."""
    step = (v_to - v_from) / (slices + 1.0)
    begin = v_from if start is None else start
    return [(span / slices, begin + step * (j + 1)) for j in range(slices)]


def segment_slices(
    length: float, v_in: float, v_out: float, rule: Classic
) -> list[tuple[float, float]]:
    """One straight segment as the classic planner cuts it: ``(duration s, speed mm/s)``
    slices of constant speed, before they are scaled to the segment's exact length.

    A trapezoid (accelerate, cruise in 0.5 s pieces, decelerate) when the segment is long
    enough; else a triangle at a peak speed (its acceleration eased by 0.9 near the limit);
    for a segment too short for five slices, a linear ramp from the boosted entry speed, or
    one slice at a constant speed."""
    vmax, a, dt = rule.speed, rule.accel, TIME_SLICE
    v0, v1 = min(v_in, vmax), min(v_out, vmax)
    t_up, t_down = (vmax - v0) / a, (vmax - v1) / a
    d_up = v0 * t_up + 0.5 * a * t_up**2
    d_down = v1 * t_down + 0.5 * a * t_down**2
    out: list[tuple[float, float]] = []
    constant = False
    if length > d_up + d_down + dt * vmax and length / vmax > 4 * dt:
        n = math.floor(t_up / dt)
        if n > 0:
            out += _ramp(v0, vmax, t_up, n)
        coast = length - d_up - d_down
        if coast > dt * vmax:
            left = coast / vmax
            while left > CRUISE_CHUNK * dt:
                out.append((CRUISE_CHUNK * dt, vmax))
                left -= CRUISE_CHUNK * dt
            out.append((left, vmax))
        n = math.floor(t_down / dt)
        if n > 0:
            out += _ramp(vmax, v1, t_down, n)
    else:
        a_local = a
        if length >= 0.9 * (d_up + d_down) and d_up + d_down > 0:
            a_local = 0.9 * (d_up + d_down) / length * a
        t_a = 0.0
        if a_local > 0:
            t_a = (math.sqrt(2 * v0 * v0 + 2 * v1 * v1 + 4 * a_local * length) - 2 * v0) / (
                2 * a_local
            )
        peak = v0 + a_local * t_a
        n_up = math.floor(t_a / dt)
        if n_up == 0:
            t_a = 0.0
        t_d = t_a - (v1 - v0) / a_local if a_local > 0 else 0.0
        n_down = math.floor(t_d / dt)
        if n_up + n_down > 4:
            if n_up > 0:
                out += _ramp(v0, peak, t_a, n_up)
            if n_down > 0:
                # The way down steps from the speed the way up reached, short of the peak (so
                # the last slice ends a step below v_out), as the published planner does.
                reached = out[-1][1] if out else v0
                out += _ramp(peak, v1, t_d, n_down, start=reached)
        else:
            v0 = (peak + v0) / 2.0  # a short segment starts boosted
            change = (v1 * v1 - v0 * v0) / (2.0 * length)
            change = max(-a, min(a, change))
            if change == 0:
                constant = True
            else:
                span = (v1 - v0) / change
                n = math.floor(span / dt)
                if n > 1:
                    out += _ramp(v0, v1, span, n)
                else:
                    v0, constant = peak, True
    if constant:
        speed = max(v0, v1) if v0 != v1 else (v0 if v0 > 0 else rule.slow)
        out = [(length / speed, speed)]
    return out


def segment_moves(
    steps: tuple[int, int], length: float, v_in: float, v_out: float, rule: Classic
) -> list[tuple[int, int, int]]:
    """The segment's ``SM`` moves ``(ms, motor 1 steps, motor 2 steps)``: the slices' ends
    rounded to whole ms and, scaled to the segment's ``steps``, to whole steps; an axis slower
    than :data:`SLOW_AXIS` held still; a move faster than :data:`MAX_STEP_RATE` lengthened."""
    slices = segment_slices(length, v_in, v_out, rule)
    ends_t = np.cumsum([d for d, _ in slices])
    ends_d = np.cumsum([d * v for d, v in slices])
    ms = [round(t * 1000.0) for t in ends_t]
    aims = [(round(f * steps[0]), round(f * steps[1])) for f in ends_d / ends_d[-1]]
    moves = []
    done = [0, 0]
    before = 0
    for when, aim in zip(ms, aims, strict=True):
        span = max(when - before, 1)
        before = when
        delta = [aim[j] - done[j] for j in (0, 1)]
        delta = [0 if abs(s / span) < SLOW_AXIS else s for s in delta]
        while max(abs(delta[0]), abs(delta[1])) / span >= MAX_STEP_RATE:
            span += 1
        done = [done[j] + delta[j] for j in (0, 1)]
        if delta != [0, 0]:
            moves.append((span, delta[0], delta[1]))
    return moves


def polyline_moves(
    points: np.ndarray, k: float, start: tuple[int, int], rule: Classic
) -> tuple[list[tuple[int, int, int]], tuple[int, int]]:
    """A polyline (mm) from the motors' ``start`` (steps) as ``SM`` moves, and where they end."""
    path, speeds = vertex_speeds(points, rule)
    here = start
    moves: list[tuple[int, int, int]] = []
    for i in range(1, len(path)):
        m = np.floor(MOTOR_AXES @ path[i] * k + 0.5).astype(np.int64)
        steps = (int(m[0]) - here[0], int(m[1]) - here[1])
        if steps == (0, 0):
            continue
        d = steps_to_xy(np.asarray(steps), k)
        part = segment_moves(steps, float(np.hypot(*d)), speeds[i - 1], speeds[i], rule)
        moves += part
        # Where the moves took the motors (an axis held still keeps what it did not take).
        here = (here[0] + sum(m[1] for m in part), here[1] + sum(m[2] for m in part))
    return moves, here


def simplify(points: np.ndarray, tolerance: float) -> np.ndarray:
    """The fewest of ``points`` (Douglas–Peucker) whose polyline stays within ``tolerance``."""
    keep = np.zeros(len(points), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(points) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        chord = points[b] - points[a]
        norm = float(np.hypot(*chord))
        rel = points[a + 1 : b] - points[a]
        if norm > 0:
            dist = np.abs(rel[:, 0] * chord[1] - rel[:, 1] * chord[0]) / norm
        else:
            dist = np.hypot(rel[:, 0], rel[:, 1])
        i = int(np.argmax(dist))
        if dist[i] > tolerance:
            keep[a + 1 + i] = True
            stack += [(a, a + 1 + i), (a + 1 + i, b)]
    return points[keep]


@dataclass
class ClassicJob:
    """The classic job's commands, each one's planned s and the pen after it."""

    lines: list[bytes] = field(default_factory=list)
    durations: list[float] = field(default_factory=list)
    pen_down: list[bool] = field(default_factory=list)
    polylines: list[np.ndarray] = field(default_factory=list)

    def add(self, line: str, seconds: float, down: bool) -> None:
        self.lines.append(f"{line}\r".encode())
        self.durations.append(seconds)
        self.pen_down.append(down)


def classic_job(paths: list[np.ndarray], profile: Profile) -> ClassicJob:
    """The AxiDraw software's job for pen-down ``paths`` (mm): for each, a pen-up move to its
    start, the pen down, the path, the pen up; then back to the park position."""
    k = profile.steps_per_mm
    down, up = Classic.pen_down(profile), Classic.pen_up(profile)
    job = ClassicJob()
    here = (0, 0)
    pin = profile["pen.pin"]

    def travel(to: np.ndarray) -> None:
        nonlocal here
        start = steps_to_xy(np.asarray(here), k)
        moves, here = polyline_moves(np.array([start, to]), k, here, up)
        for ms, a, b in moves:
            job.add(f"SM,{ms},{a},{b}", ms / 1000.0, False)

    for path in paths:
        travel(path[0])
        ms = max(1, round(1000.0 * profile.pen_time(True)))
        job.add(f"SP,0,{ms},{pin}", ms / 1000.0, True)
        polyline = simplify(path, POLYLINE_TOLERANCE)
        job.polylines.append(polyline)
        start = steps_to_xy(np.asarray(here), k)
        moves, here = polyline_moves(np.vstack([start, polyline[1:]]), k, here, down)
        for ms_, a, b in moves:
            job.add(f"SM,{ms_},{a},{b}", ms_ / 1000.0, True)
        ms = max(1, round(1000.0 * profile.pen_time(False)))
        job.add(f"SP,1,{ms},{pin}", ms / 1000.0, False)
    if profile["motion.park"]:
        travel(np.array([profile["motion.park_x"], profile["motion.park_y"]]))
    return job


def run_classic(job: ClassicJob, profile: Profile, name: str) -> tuple[np.ndarray, float]:
    """Stream ``job`` into a fresh simulated EBB: the executed ``t, x, y, pen`` every 1 ms
    (stream clock, 0 at its start) and the job's executed duration, s."""
    from sim.ebb.device import SimulatedEBB
    from sim.ebb.transport import attach_device

    device = SimulatedEBB(pen_pin=profile["pen.pin"])  # wired as the profile says
    link = serial.serial_for_url(attach_device(device, name), timeout=0.01)
    pens = {
        True: next(
            (line, d) for line, d in zip(job.lines, job.durations, strict=True) if b"SP,0" in line
        ),
        False: next(
            (line, d) for line, d in zip(job.lines, job.durations, strict=True) if b"SP,1" in line
        ),
    }
    try:
        streamer = EBBStreamer(link, profile, pens)
        streamer.connect()
        report = streamer.stream(
            job.lines,
            durations=job.durations,
            preamble=[pens[False][0]],
            pen_down=job.pen_down,
        )
    finally:
        link.close()
    trace = device.recorder.trace()
    keep = np.unique(np.append(np.arange(0, len(trace.t), TRACE_TICKS), len(trace.t) - 1))
    motors = np.column_stack([trace.motor1[keep], trace.motor2[keep]])
    xy = steps_to_xy(motors, profile.steps_per_mm)
    up = profile.servo_position(profile["pen.up"])
    down = profile.servo_position(profile["pen.down"])
    width = trace.pen[keep]
    pen = (np.abs(width - down) < np.abs(width - up)).astype(float)
    rows = np.column_stack([trace.t[keep] - report.started, xy, pen])
    return rows[rows[:, 0] >= 0], report.duration


# -- the lower bound --------------------------------------------------------------------------

BOUND_STEP = 0.0005
"""s between the samples of each run's motion in :func:`lower_bound`."""


def trapezoid_time(distance: float, speed: float, accel: float) -> float:
    """The least time, s, to move ``distance`` from rest to rest at ``speed`` and ``accel``."""
    if distance <= 0:
        return 0.0
    if distance >= speed * speed / accel:
        return distance / speed + speed / accel
    return 2.0 * math.sqrt(distance / accel)


def run_scale(p: np.ndarray, du: float, speed: float, accel: float) -> float:
    """The least time scale ``s ≥ 1`` at which motion ``p`` (mm, one sample every ``du`` s)
    keeps its speed and acceleration along both motors within ``speed`` and ``accel``."""
    motors = p @ MOTOR_AXES.T
    v = np.gradient(motors, du, axis=0)
    a = np.gradient(v, du, axis=0)
    return max(1.0, float(np.abs(v).max()) / speed, math.sqrt(float(np.abs(a).max()) / accel))


def lower_bound(tag: tagbot.Tag, setpoints: Any, profile: Profile) -> tuple[float, list[float]]:
    """The least job time the machine's limits allow (module docstring), and each run's least
    time scale. Each run's motion is the tag's plan on the run's clock (``Run.clock``, scale 1)
    from where it is over one motor step from its first point to where it last is from its end
    point (what is within a step of an end takes no step)."""
    from tagbot.model.motion import evaluate_plan

    k = profile.steps_per_mm
    travel_v, travel_a = profile["limits.travel_speed"], profile["limits.travel_acceleration"]
    pens = profile.pen_time(True) + profile.pen_time(False)
    here = np.zeros(2)
    total, scales = 0.0, []

    def travel(to: np.ndarray) -> float:
        along = np.abs(MOTOR_AXES @ (to - here)).max()
        return trapezoid_time(float(along), travel_v, travel_a)

    for run in setpoints.runs:
        clock = run.clock
        u = np.arange(0.0, clock.duration, BOUND_STEP)
        u = np.append(u[u < clock.duration - 1e-6], clock.duration)
        p, _ = evaluate_plan(tag.plans[run.plan], clock.tag_time(u), tag.size)
        p = p @ setpoints.matrix.T + setpoints.offset
        away = np.abs((p - p[0]) @ MOTOR_AXES.T).max(axis=1) > 1.0 / k
        from_end = np.abs((p - p[-1]) @ MOTOR_AXES.T).max(axis=1) > 1.0 / k
        if away.any():
            first = int(np.argmax(away)) - 1
            last = len(u) - int(np.argmax(from_end[::-1]))
            part = p[max(first, 0) : last + 1]
            s = run_scale(
                part, BOUND_STEP, profile["limits.draw_speed"], profile["limits.draw_acceleration"]
            )
            drawn = float(u[min(last, len(u) - 1)] - u[max(first, 0)])
        else:  # a dot
            s, drawn = 1.0, 0.0
        scales.append(s)
        total += travel(p[0]) + pens + s * drawn
        here = p[-1]
    if profile["motion.park"]:
        total += travel(np.array([profile["motion.park_x"], profile["motion.park_y"]]))
    return total, scales


# -- the comparisons --------------------------------------------------------------------------


def step_ceiling(t: np.ndarray, xy: np.ndarray, k: float, at: np.ndarray | None = None) -> float:
    """The speed SNR, dB, of a planned run ``(t, xy)`` against itself rounded to whole motor
    steps (``k`` per mm along x ± y) at the instants ``at`` (plan clock; default ``t``): what
    a motion following the plan exactly scores, over the span it was drawn in."""
    at = t if at is None else at
    exact = np.column_stack([np.interp(at, t, xy[:, 0]), np.interp(at, t, xy[:, 1])])
    rounded = steps_to_xy(np.floor(exact @ MOTOR_AXES.T * k + 0.5), k)
    c = compare_execution([(t, xy)], np.column_stack([at, rounded, np.ones(len(at))]))
    return math.inf if c.speed_snr_db is None else c.speed_snr_db


STEP_OFFSETS = np.linspace(0.0, 0.75, 4)
"""Fractions of a motor step the run is moved by, on each motor, for :func:`step_band`."""


def step_band(
    t: np.ndarray, xy: np.ndarray, k: float, at: np.ndarray | None = None
) -> tuple[float, float]:
    """The least and the most :func:`step_ceiling` of the run moved by a fraction of a motor
    step on each motor (:data:`STEP_OFFSETS`): where a run starts on the step grid is chance
    (its placement), and on a short slow run it alone moves an exact follower's score by a few
    dB. ``at``: the executed run's instants on the plan's clock (its pen-down span), so that
    the band and the run are judged over the same samples."""
    scores = [
        step_ceiling(t, xy + steps_to_xy(np.array([a, b]), k), k, at)
        for a in STEP_OFFSETS
        for b in STEP_OFFSETS
    ]
    return min(scores), max(scores)


def drawn_band(
    report: dict[str, Any],
    run: dict[str, Any],
    plan: tuple[np.ndarray, np.ndarray],
    executed: np.ndarray,
    k: float,
) -> tuple[float, float]:
    """:func:`step_band` of the report's ``run`` (one of ``report["runs"]``, planned as
    ``plan``) over the instants its pen was down in ``executed``, on the plan's clock: the
    samples the run's own figure is taken over (beyond the plan's ends the plan is at rest)."""
    drawn = executed_runs(executed)[report["runs"].index(run)]
    at = drawn[:, 0] - (run["executed_start"] - run["planned_start"])
    return step_band(*plan, k, at)


STRETCH_COARSE = np.linspace(-0.08, 0.08, 9)
STRETCH_FINE = np.linspace(-0.015, 0.015, 7)
STRETCH_FINEST = np.linspace(-0.003, 0.003, 7)
"""Relative stretches of a planned run tried around the executed/planned duration ratio, then
around the best one found, twice."""


def shape_snr(t: np.ndarray, xy: np.ndarray, plan: int, run: np.ndarray, ratio: float) -> float:
    """The best speed SNR, dB, of one executed pen-down ``run`` (``t, x, y``) against the
    planned run ``(t, xy)`` stretched in time about its start: the stretch searched around
    ``ratio`` (coarse, then finer twice; no stretch also tried), so the figure is the speed
    profile's shape at any pace."""
    rows = np.column_stack([run, np.ones(len(run))])

    def snr(r: float) -> float:
        c = compare_execution([(t[0] + (t - t[0]) * r, xy)], rows, plans=[plan])
        return -math.inf if c.speed_snr_db is None else c.speed_snr_db

    best = max((ratio * (1 + x) for x in STRETCH_COARSE), key=snr)
    best = max((best * (1 + x) for x in STRETCH_FINE), key=snr)
    return max([snr(1.0)] + [snr(best * (1 + x)) for x in STRETCH_FINEST])


def against_writer(
    planned: list[tuple[np.ndarray, np.ndarray]], plans: list[int], executed: np.ndarray
) -> dict[str, Any]:
    """An executed trace against the writer's motion (``planned``, per run): as drawn (each
    run aligned at its onset), and each run's speed profile shape (:func:`shape_snr`)."""
    direct = compare_execution(planned, executed, plans=plans)
    runs = [r.snr_db for r in direct.runs if r.snr_db is not None]
    shapes = [
        shape_snr(t, xy, plan, run, r.executed_duration / r.planned_duration)
        for (t, xy), plan, run, r in zip(
            planned, plans, executed_runs(executed), direct.runs, strict=False
        )
        if r.planned_duration > 0
    ]
    return {
        "snr_db": direct.speed_snr_db,
        "run_snr_min_db": min(runs, default=math.nan),
        "shape_snr_min_db": min(shapes, default=math.nan),
        "shape_snr_median_db": float(np.median(shapes)) if shapes else math.nan,
        "drawing_s": direct.executed_duration,
        "drawing_ratio": direct.duration_ratio,
        "dev_max_mm": direct.deviation_max,
        "runs_executed": direct.executed_runs,
    }


def measure(name: str, tag: tagbot.Tag, profile_name: str, scratch: Path) -> dict[str, Any]:
    """Both ways of drawing ``tag`` on the simulated board, and the lower bound."""
    slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
    profile = load_profile(profile_name)
    job = prepare(tag, profile=profile_name)
    planned = job._planned_runs()
    plans = [run.plan for run in job.job.runs]
    row: dict[str, Any] = {"tag": name, "runs": len(plans), "moves": len(job.job.entries)}

    out = scratch / slug
    start = time.perf_counter()
    draw(tag, out, device="axidraw", profile=profile_name, pictures=False)
    row["tagbot_wall_s"] = time.perf_counter() - start
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    snrs = [r["speed_snr_db"] for r in report["runs"] if r.get("speed_snr_db") is not None]
    row.update(
        report_snr_db=report["speed_snr_db"],
        report_run_snr_min_db=min(snrs, default=math.nan),
        report_dev_mean_mm=report["path_deviation_mean_mm"],
        report_dev_max_mm=report["path_deviation_max_mm"],
        planned_s=report["planned_duration_s"],
        executed_s=report["executed_duration_s"],
        planned_drawing_s=report["planned_drawing_s"],
        completed=report["completed"],
    )
    details = report["details"]
    margins = [
        m - q
        for m, q in zip(
            details["run_moves_speed_snr_db"], details["run_steps_speed_snr_db"], strict=True
        )
        if m is not None and q is not None
    ]
    row.update(
        fifo=details["fifo"],
        profile_fifo=int(profile["serial.fifo"]),
        draw_moves=details["draw_moves"],
        moves_margin_min_db=min(margins, default=math.inf),
    )
    worst = min(report["runs"], key=lambda r: r["speed_snr_db"] or math.inf, default=None)
    if worst is not None and worst["plan"] in plans:
        t, xy = planned[plans.index(worst["plan"])]
        executed = np.loadtxt(out / "executed.csv", delimiter=",", skiprows=1, ndmin=2)
        low, high = drawn_band(report, worst, (t, xy), executed, profile.steps_per_mm)
        row.update(worst_run_step_band_low_db=low, worst_run_step_band_high_db=high)
    executed = np.loadtxt(out / "executed.csv", delimiter=",", skiprows=1, ndmin=2)
    row.update({f"tagbot_{k}": v for k, v in against_writer(planned, plans, executed).items()})
    bound, scales = lower_bound(tag, job.setpoints, profile)
    row.update(bound_s=bound, bound_ratio=row["executed_s"] / bound)
    row["scale_vs_bound"] = max(
        (run.scale / s for run, s in zip(job.setpoints.runs, scales, strict=True)), default=1.0
    )

    start = time.perf_counter()
    classic = classic_job([xy for _, xy in planned], profile)
    trace, duration = run_classic(classic, profile, re.sub(r"\W", "_", f"bench_{slug}"))
    row["classic_wall_s"] = time.perf_counter() - start
    row.update(classic_s=duration, classic_moves=len(classic.lines))
    row.update({f"classic_{k}": v for k, v in against_writer(planned, plans, trace).items()})
    return row


# -- printing -----------------------------------------------------------------------------------


def print_rows(rows: list[dict[str, Any]]) -> None:
    print(
        "| tag | runs | tagbot: worst run SNR dB (≥ 35) [an exact follower on its steps] |"
        " deviation mean / max mm (≤ 0.02) |"
        " job s / bound s (≤ 1.1) | classic: job s (moves) |"
        " vs writer, SNR as drawn dB: tagbot / classic | shape SNR dB: tagbot / classic |"
        " drawing time / plan's: tagbot / classic |"
    )
    print("|---|---:|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = r["bound_ratio"]
        print(
            f"| {r['tag']} | {r['runs']} |"
            f" {r['report_run_snr_min_db']:.1f} {mark(r['report_run_snr_min_db'] >= SNR_GOAL)}"
            f" [{r.get('worst_run_step_band_low_db', math.nan):.1f}"
            f" to {r.get('worst_run_step_band_high_db', math.nan):.1f}] |"
            f" {r['report_dev_mean_mm']:.4f} / {r['report_dev_max_mm']:.4f}"
            f" {mark(r['report_dev_max_mm'] <= DEVIATION_GOAL)} |"
            f" {r['executed_s']:.2f} / {r['bound_s']:.2f} = {ratio:.3f}"
            f" {mark(ratio <= BOUND_GOAL)} |"
            f" {r['classic_s']:.2f} ({r['classic_moves']}) |"
            f" {r['tagbot_snr_db']:.1f} / {r['classic_snr_db']:.1f} |"
            f" {r['tagbot_shape_snr_median_db']:.1f} ({r['tagbot_shape_snr_min_db']:.1f}) /"
            f" {r['classic_shape_snr_median_db']:.1f} ({r['classic_shape_snr_min_db']:.1f}) |"
            f" {r['tagbot_drawing_ratio']:.3f} / {r['classic_drawing_ratio']:.3f} |"
        )


def print_totals(rows: list[dict[str, Any]]) -> None:
    if not rows:
        return
    n = len(rows)
    snr_ok = sum(r["report_run_snr_min_db"] >= SNR_GOAL for r in rows)
    dev_ok = sum(r["report_dev_max_mm"] <= DEVIATION_GOAL for r in rows)
    bound_ok = sum(r["bound_ratio"] <= BOUND_GOAL for r in rows)
    print()
    print(
        f"- {n} tags: worst-run speed SNR ≥ {SNR_GOAL:g} dB on {snr_ok}, deviation ≤"
        f" {DEVIATION_GOAL:g} mm on {dev_ok}, job ≤ {BOUND_GOAL:g} x the bound on {bound_ok}"
    )
    margin = min(rows, key=lambda r: r["moves_margin_min_db"])
    deeper = [r for r in rows if r["fifo"] > r["profile_fifo"]]
    print(
        f"- the moves' own speed error under the steps' by {margin['moves_margin_min_db']:.1f} dB"
        f" at least ({margin['tag']}); FIFO deeper than the profile's on {len(deeper)} tags"
        f" ({', '.join(str(r['fifo']) for r in deeper) or '-'})"
    )
    worst = min(rows, key=lambda r: r["report_run_snr_min_db"])
    print(
        f"- worst run SNR {worst['report_run_snr_min_db']:.1f} dB ({worst['tag']});"
        f" largest deviation {max(r['report_dev_max_mm'] for r in rows):.4f} mm;"
        f" job / bound {min(r['bound_ratio'] for r in rows):.3f}-"
        f"{max(r['bound_ratio'] for r in rows):.3f}"
    )
    for who in ("tagbot", "classic"):
        snr = np.median([r[f"{who}_snr_db"] for r in rows])
        shape = np.median([r[f"{who}_shape_snr_median_db"] for r in rows])
        ratio = np.median([r[f"{who}_drawing_ratio"] for r in rows])
        job = sum(r["executed_s" if who == "tagbot" else "classic_s"] for r in rows)
        print(
            f"- {who}: median SNR against the writer's speed {snr:.1f} dB as drawn,"
            f" {shape:.1f} dB in shape (median of the tags' median runs);"
            f" median drawing time / plan's {ratio:.3f};"
            f" {job:.0f} s of jobs"
        )
    wall = sum(r["wall_s"] for r in rows)
    drawing = sum(r["tagbot_wall_s"] + r["classic_wall_s"] for r in rows)
    print(f"- wall time {wall:.0f} s (fitting, both jobs and the comparisons; the two jobs on the")
    print(f"  simulated board {drawing:.0f} s)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gml", type=int, default=45, help="GML tags from ../shared/data")
    parser.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    parser.add_argument("--profile", default="default", help="an AxiDraw profile (name or path)")
    parser.add_argument("--quick", action="store_true", help="letter-b and cae only")
    parser.add_argument("--tags", default="", help="only tags whose name holds one of A,B,...")
    parser.add_argument("--csv", type=Path, help="write every row to this CSV file")
    args = parser.parse_args()
    tags: list[tuple[str, Callable[[], tagbot.Tag]]] = example_tags()
    if args.quick:
        tags = [t for t in tags if t[0] in ("letter-b.json", "cae.json")]
    else:
        tags += gml_tags(args.data, args.gml)
    wanted = [w for w in args.tags.split(",") if w]
    if wanted:
        tags = [t for t in tags if any(w in t[0] for w in wanted)]
    rows: list[dict[str, Any]] = []
    failures: list[str] = []
    with tempfile.TemporaryDirectory(prefix="bench_axidraw_") as scratch:
        for name, load in tags:
            try:
                start = time.perf_counter()
                rows.append(measure(name, load(), args.profile, Path(scratch)))
                rows[-1]["wall_s"] = time.perf_counter() - start
            except Exception as e:  # a failure is a figure, never dropped
                failures.append(f"{name}: {type(e).__name__}: {e}")
            print(f"  {name} done", file=sys.stderr, flush=True)
    print(f"AxiDraw ({args.profile} profile) on the simulated EBB 3.0.3; ✓ goal met, ✗ missed")
    print_rows(rows)
    print_totals(rows)
    for failure in failures:
        print(f"FAILED {failure}")
    if args.csv and rows:
        with open(args.csv, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
