"""Both machines draw a plan that touches down and lifts off moving over its ink window only,
from rest to rest, on the plan's own path (tagbot.model.easing)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tagbot import arm, plotter
from tagbot.metrics import densify
from tagbot.model.easing import EASE
from tagbot.model.motion import evaluate_plan
from tagbot.model.plan import Plan, Tag
from tests.model.test_ink import lifted


def lifted_tag() -> Tag:
    """One hook whose pen is down from 0.15 to 0.45 s into its motion (moving at both ends),
    then a plan drawn from rest to rest."""
    hook = lifted(start=0.0)
    rest = Plan([[10.0, 20.0], [30.0, 25.0]], [0.0], [np.log(0.2)], [0.3], [0.2], [-0.2], 2.0)
    return Tag((hook, rest))


def ink_path(tag: Tag, k: int, matrix, offset) -> cKDTree:
    """The placed ink of plan ``k``, densely sampled."""
    down, up = tag.plans[k].ink_window(tag.size)
    xy, _ = evaluate_plan(tag.plans[k], np.linspace(down, up, 20001), tag.size)
    return cKDTree(densify(xy @ matrix.T + offset, 1e-3))


def test_the_plotter_eases_in_and_out_along_the_ink() -> None:
    tag = lifted_tag()
    setpoints = plotter.place(tag, plotter.load_profile())
    hook, rest = setpoints.runs
    assert (hook.clock.ease_in, hook.clock.ease_out) == (EASE, EASE)
    assert rest.clock.ease_in == rest.clock.ease_out == 0.0
    down, up = tag.plans[0].ink_window(tag.size)
    assert hook.span == (down, up)  # moving ends: nothing to trim
    # From rest, to rest, and the plan's own speed (retimed) between the ramps.
    assert np.all(hook.v[0] == 0.0) and np.hypot(*hook.v[-1]) < 0.1  # (last kept step)
    down, up = tag.plans[0].ink_window(tag.size)
    # A stepper starts at a constant acceleration: each ramp covers 2/3 of EASE of the plan.
    assert not hook.clock.jerk_limited
    middle = (hook.tag_t > down + 2 * EASE / 3) & (hook.tag_t < up - 2 * EASE / 3)
    assert middle.sum() > 5
    _, v = evaluate_plan(tag.plans[0], hook.tag_t[middle], tag.size)
    assert np.allclose(hook.v[middle], v @ setpoints.matrix.T / hook.scale)
    # Every setpoint is on the ink, none in the air.
    path = ink_path(tag, 0, setpoints.matrix, setpoints.offset)
    assert path.query(hook.xy)[0].max() < 2e-3
    assert np.all((hook.tag_t >= down - 1e-9) & (hook.tag_t <= up + 1e-9))
    plotter.build_program(setpoints, plotter.load_profile())  # a valid program


def test_the_arm_eases_in_and_out_along_the_ink() -> None:
    tag = lifted_tag()
    profile = arm.load_profile()
    program = arm.build_program(tag, profile)
    sp = program.setpoints
    clock = sp.run_clocks[0]
    assert (clock.ease_in, clock.ease_out) == (EASE, EASE)
    assert sp.run_clocks[1].ease_in == sp.run_clocks[1].ease_out == 0.0
    rows = np.flatnonzero(sp.plan == 0)
    assert np.all(sp.pen[rows])
    assert np.hypot(*sp.v[rows[0]]) == 0.0 and np.hypot(*sp.v[rows[-1]]) < 1e-6
    down, up = tag.plans[0].ink_window(tag.size)
    start, _ = evaluate_plan(tag.plans[0], np.array([down]), tag.size)
    placed = start @ sp.placement.matrix.T + sp.placement.offset
    assert np.allclose(sp.xy[rows[0]], placed[0])
    path = ink_path(tag, 0, sp.placement.matrix, sp.placement.offset)
    assert path.query(sp.xy[rows])[0].max() < 2e-3
    # The run lasts its clock's length at its time scale: longer than the window by the ramps.
    s = sp.run_scales[0]
    assert len(rows) - 1 == int(np.ceil(clock.duration * s / profile.period - 1e-9))
    assert clock.duration == pytest.approx(up - down + EASE)
