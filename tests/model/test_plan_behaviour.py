"""Plans drawn one after another, ink windows and sampling, as a user sees them (issue 34)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagbot.errors import PlanError
from tagbot.model import Plan, Tag, sequence


def _stroke(x: float = 0.0, ink: tuple[float, float] | None = None) -> Plan:
    return Plan(
        targets=[[x, 0.0], [x + 10.0, 0.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        ink=ink,
    )


def test_back_to_back_plans_with_no_lift_are_a_tag() -> None:
    tag = sequence([_stroke(), _stroke(20.0)], 0.0)
    assert tag.plans[1].start == tag.plans[0].end(tag.size)


def test_a_plan_touching_down_before_the_last_lifts_off_is_refused() -> None:
    first = _stroke()
    size = math.hypot(30.0, 0.0)
    lift_off = first.end(size)
    with pytest.raises(PlanError) as raised:
        Tag((first, _stroke(20.0).at(lift_off - 1e-3)))
    assert str(raised.value) == (
        f"plans[1]: the pen touches down at {lift_off - 1e-3:.6g} s, before plans[0] lifts it off"
        f" ({lift_off:.6g} s); plans are drawn one after another"
    )
    Tag((first, _stroke(20.0).at(lift_off)))  # at the very instant: accepted


def test_ink_windows_decide_where_the_pen_lands_and_lifts_moving() -> None:
    size = 10.0
    whole = _stroke()
    end = whole.end(size)
    assert whole.moving_ends(size) == (False, False)
    assert _stroke(ink=(0.0, end + 1.0)).moving_ends(size) == (False, False)
    assert _stroke(ink=(0.0, end / 2)).moving_ends(size) == (False, True)
    assert _stroke(ink=(0.05, end + 1.0)).moving_ends(size) == (True, False)
    assert _stroke(ink=(0.05, end / 2)).moving_ends(size) == (True, True)
    assert _stroke(ink=(0.05, end / 2)).ink_window(size) == (0.05, end / 2)
    assert _stroke(ink=(0.05, end + 1.0)).ink_window(size) == (0.05, end)


def test_sampling_defaults_to_10_ms() -> None:
    tag = Tag((_stroke(),))
    motion = tag.sample()
    assert np.allclose(np.diff(motion.t), 0.01)
    assert np.array_equal(motion.xy, tag.sample(0.01).xy)
