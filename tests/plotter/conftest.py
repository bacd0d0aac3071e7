"""A tiny fake machine and a tiny hand-made tag for exact-output tests."""

from __future__ import annotations

import math

import pytest

from tagbot.model import Plan, Tag
from tagbot.plotter import load_profile

TINY = """
[bed]
x_min = 0.0
x_max = 100.0
y_min = 0.0
y_max = 50.0
margin = 5.0
y_down = false

[limits]
x_max_feed = 60000.0
y_max_feed = 60000.0
x_acceleration = 100000.0
y_acceleration = 100000.0
x_steps_per_mm = 100.0
y_steps_per_mm = 100.0

[pen]
type = "servo"
up = 50.0
down = 30.0
dwell = 0.2

[motion]
dt = 0.05
travel_feed = 1200.0
park = true
park_x = 0.0
park_y = 0.0
"""


def straight_tag(length: float = 10.0, start: float = 0.0) -> Tag:
    """One plan, one straight stroke along +x from (0, 0)."""
    plan = Plan(
        targets=[[0.0, 0.0], [length, 0.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        start=start,
    )
    return Tag(plans=(plan,))


def two_plan_tag() -> Tag:
    """Two plans: a stroke along +x, then one along +y, with a pen lift between."""
    first = straight_tag().plans[0]
    second = Plan(
        targets=[[10.0, 0.0], [10.0, 5.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        start=first.end(10.0) + 0.5,
    )
    return Tag(plans=(first, second))


@pytest.fixture
def tiny_file(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY, encoding="utf-8")
    return path


@pytest.fixture
def tiny(tiny_file):
    return load_profile(tiny_file)
