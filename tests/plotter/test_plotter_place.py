"""Placement (aspect, margins, y direction) and uniform retiming to the machine's limits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tagbot
from tagbot.plotter import load_profile, place
from tagbot.plotter.place import FINE_STEP, limit_scale, segment_speed_cap

from .conftest import straight_tag, two_plan_tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"


def _extent(setpoints):
    xy = np.concatenate([r.xy for r in setpoints.runs])
    return xy.min(axis=0), xy.max(axis=0)


def test_fit_keeps_aspect_and_margins():
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    profile = load_profile()
    placed = place(tag, profile)
    low, high = _extent(placed)
    margin = profile["bed.margin"]
    x_min, x_max, y_min, y_max = profile.bed
    assert low[0] >= x_min + margin - 1e-6 and high[0] <= x_max - margin + 1e-6
    assert low[1] >= y_min + margin - 1e-6 and high[1] <= y_max - margin + 1e-6
    # One side touches its margins (fit), within the fine sampling's resolution.
    touches_x = np.isclose(high[0] - low[0], x_max - x_min - 2 * margin, atol=0.05)
    touches_y = np.isclose(high[1] - low[1], y_max - y_min - 2 * margin, atol=0.05)
    assert touches_x or touches_y
    # Aspect kept: the tag's own extent times one scale.
    raw = np.concatenate([tag.sample(0.002).xy[tag.sample(0.002).pen == 1]])
    ratio = (high - low) / np.ptp(raw, axis=0)
    assert ratio[0] == pytest.approx(ratio[1], rel=2e-3)
    assert np.allclose(placed.matrix.T @ placed.matrix, placed.size**2 * np.eye(2))


def test_y_down_mirrors(tiny_file):
    up = place(two_plan_tag(), load_profile(tiny_file, ["place.align=top-left"]))
    down = place(
        two_plan_tag(), load_profile(tiny_file, ["place.align=top-left", "bed.y_down=true"])
    )
    for a, b in zip(up.runs, down.runs, strict=True):
        assert np.allclose(b.xy[:, 0], a.xy[:, 0])
        assert np.allclose(b.xy[:, 1], 50.0 - a.xy[:, 1])
        assert np.allclose(b.v[:, 1], -a.v[:, 1])
    # Top-left on a y-down machine is near machine y = margin.
    assert min(r.xy[:, 1].min() for r in down.runs) == pytest.approx(5.0, abs=1e-6)


def test_rotation_and_explicit_scale(tiny_file):
    profile = load_profile(tiny_file, ["place.scale=2", "place.rotation=90"])
    placed = place(straight_tag(), profile)
    run = placed.runs[0]
    assert placed.size == 2.0
    assert np.ptp(run.xy[:, 0]) == pytest.approx(0.0, abs=1e-9)
    assert np.ptp(run.xy[:, 1]) == pytest.approx(20.0, abs=1e-3)
    assert run.xy[-1, 1] > run.xy[0, 1]  # +x of the tag became +y


def test_scale_is_one_when_slow_enough(tiny):
    placed = place(straight_tag(), tiny)
    assert placed.scale == 1.0
    assert placed.runs[0].t[1] - placed.runs[0].t[0] == pytest.approx(tiny.dt)


@pytest.mark.parametrize(
    "overrides",
    [
        ["limits.x_max_feed=3000"],  # speed-bound
        ["limits.x_acceleration=200", "limits.y_acceleration=200"],  # acceleration/segment-bound
        ["limits.planner_blocks=1", "motion.dt=0.002"],  # the look-ahead cap dominates
    ],
)
def test_retimed_motion_within_limits(tiny_file, overrides):
    profile = load_profile(tiny_file, overrides)
    tag = two_plan_tag()
    placed = place(tag, profile)
    assert placed.scale > 1.0
    if "limits.planner_blocks=1" in overrides:
        assert placed.limits["segment"] == max(placed.limits.values())
    assert placed.scale == pytest.approx(max(placed.limits.values()), rel=0.02)
    vmax = np.array(profile.max_speed)
    amax = np.array(profile.max_acceleration)
    for run in placed.runs:
        # Analytic velocity after retiming, and its differences at a fine retimed step.
        assert np.all(np.abs(run.v) <= vmax * (1 + 1e-9))
        assert np.all(np.abs(np.diff(run.xy, axis=0)) / placed.dt <= vmax * (1 + 1e-6))
        speed, cap = segment_speed_cap(run.xy, placed.dt, profile)
        assert np.all(speed <= cap * (1 + 1e-6))
    # Acceleration measured independently at a finer step of the retimed clock.
    for k, plan in enumerate(tag.plans):
        t = np.arange(plan.start, plan.end(tag.size), FINE_STEP / 4)
        _, v = tagbot.model.motion.evaluate_plan(plan, t, tag.size)
        v = v @ placed.matrix.T / placed.scale
        acc = np.diff(v, axis=0) / (FINE_STEP / 4 * placed.scale)
        assert np.all(np.abs(acc) <= amax * 1.02), k
    # Retiming keeps the shape: each run still ends where it did, at a scaled clock.
    unscaled = place(tag, load_profile(tiny_file))
    assert np.allclose(placed.runs[0].xy[-1], unscaled.runs[0].xy[-1], atol=1e-3)


def test_limit_scale_formulas(tiny):
    v = np.array([[0.0, 0.0], [2000.0, 0.0], [0.0, 0.0]])  # mm/s, samples 1 ms apart
    limits = limit_scale(v, 0.001, tiny)
    assert limits["speed"] == pytest.approx(2.0)  # 1000 mm/s allowed
    assert limits["acceleration"] == pytest.approx(np.sqrt(2e6 / 1e5))
    # Cap: v ≤ 2·a·B·dt = 2 · 1e5 · 15 · 0.05 = 150000 mm/s.
    assert limits["segment"] == 1.0


def test_junction_limit_on_curves(tiny_file):
    from tagbot.model import Plan, Tag
    from tagbot.plotter.place import junction_speed

    curve = Plan(
        targets=[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]],
        dt=[0.0, 0.15],
        mu=[np.log(0.2)] * 2,
        sigma=[0.3] * 2,
        phi1=[0.6, 0.5],
        phi2=[-0.6, -0.5],
    )
    tag = Tag(plans=(curve,))
    profile = load_profile(tiny_file, ["limits.junction_deviation=0.0005"])
    placed = place(tag, profile)
    assert placed.limits["junction"] > 1.0
    assert placed.scale == pytest.approx(max(placed.limits.values()))
    entry, limit, deflection = junction_speed(placed.runs[0].xy, profile)
    gentle = deflection < np.pi / 4
    assert np.all(entry[gentle] / placed.dt <= limit[gentle] * (1 + 1e-6))
    # A looser machine does not need the junction slow-down.
    assert place(tag, load_profile(tiny_file)).limits["junction"] == 1.0
