"""Timed tags in the studio: plans whose motions overlap in the air keep their places through
loading and editing; a pen lift runs from a lift-off to the next touch-down."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.gesture.vary import in_order, lifts
from tagbot.io.planfile import tag_from_dict, tag_to_dict
from tagbot.model import Plan, Tag, random_timed_plan
from tests.studio.conftest import Running


def overlapping_tag() -> Tag:
    """Two timed plans: the first lifts off at 60 % of its motion, the second touches down at
    30 % of its own, 0.05 s later, so the second starts before the first's motion ends."""
    rng = np.random.default_rng(4)
    plans = []
    for k, (down, up) in enumerate([(0.0, 0.6), (0.3, 1.0)]):
        p = random_timed_plan(rng)
        duration = p.end(1e3) - p.start
        ink = (down * duration, up * duration)
        plans.append(Plan(p.targets + 120.0 * k, p.dt, p.mu, p.sigma, p.phi1, p.phi2, 0.0, ink))
    tag = in_order(plans, [0.05])
    assert tag.plans[1].start < tag.plans[0].end(tag.size)  # the motions overlap in the air
    return tag


def windows(tag: Tag) -> list[float]:
    """Every plan's touch-down and lift-off, one after the other."""
    return [edge for plan in tag.plans for edge in plan.ink_window(tag.size)]


def test_a_timed_tag_loads_and_edits_without_moving(running: Running) -> None:
    tag = overlapping_tag()
    running.load(tag_to_dict(tag))
    assert windows(tag_from_dict(running.plan())) == pytest.approx(windows(tag), abs=1e-9)
    design = running.state()["design"]
    assert design["plans"][1]["lift"] == pytest.approx(0.05, abs=1e-12)
    # Moving the second plan's last target leaves the first plan and the lift where they were.
    to = [float(c) for c in tag.plans[1].targets[-1] + (3.0, -2.0)]
    response = running.client.patch(
        "/api/plan",
        json={
            "ops": [
                {"op": "move_target", "plan": 1, "index": -1 + len(tag.plans[1].targets), "to": to}
            ]
        },
    )
    assert response.is_success, response.text
    edited = tag_from_dict(running.plan())
    assert edited.plans[0].start == tag.plans[0].start
    assert edited.plans[0].ink == pytest.approx(tag.plans[0].ink)
    assert lifts(edited) == pytest.approx([0.05], abs=1e-12)
    # A new lift: touch-down minus lift-off, as the samples show it.
    lift = {"op": "lift", "plan": 1, "seconds": 0.4}
    assert running.client.patch("/api/plan", json={"ops": [lift]}).is_success
    state = running.state()
    motion = state["motion"]
    pen = np.array(motion["pen"])
    t = np.array(motion["t"])
    down = np.flatnonzero(np.diff(pen) == 1) + 1
    up = np.flatnonzero(np.diff(pen) == -1) + 1
    gap = t[down[-1]] - t[up[0]]
    assert gap == pytest.approx(0.4, abs=2.0 * motion["dt"])
    assert lifts(tag_from_dict(state["tag"])) == pytest.approx([0.4], abs=1e-12)
