"""Placement and the program's refusals at their bounds (issue 34): the largest scale the area's
margins allow is exactly the boundary, and a placement that runs out of reach is named."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tagbot.arm import build_program, load_profile
from tagbot.arm.place import Placement, place, safe
from tagbot.errors import PlacementError
from tagbot.model.motion import evaluate_plan

from .conftest import hook_from_its_end, small_tag

AREA = ["area.x_min=-20", "area.x_max=20", "area.y_min=150", "area.y_max=190"]
"""A 40 by 40 mm sheet (20 by 20 inside its 10 mm margin) well inside the arm's reach and joint
limits: only the margins bound the tag (10 by 6 units, wider than tall: x binds)."""


def test_the_largest_scale_is_where_the_margins_stop_the_tag() -> None:
    largest = float(place(small_tag(), load_profile(None, AREA)).largest)
    at = place(small_tag(), load_profile(None, [*AREA, f"place.scale={largest!r}"]))
    # At it the tag spans the room between the side margins (less its 1 ms sampling pad),
    # centred; its height is 0.6 of that.
    x0, x1, y0, y1 = at.box
    assert x0 == pytest.approx(-10.0, abs=1e-3) and x1 == pytest.approx(10.0, abs=1e-3)
    assert x0 >= -10.0 and x1 <= 10.0 and x0 == pytest.approx(-x1, abs=1e-9)
    assert (y1 - y0) == pytest.approx(0.6 * (x1 - x0), rel=1e-3)
    assert at.mm_per_unit == largest
    beyond = f"{largest * (1 + 1e-9)!r}"
    with pytest.raises(PlacementError) as raised:
        place(small_tag(), load_profile(None, [*AREA, f"place.scale={beyond}"]))
    assert str(raised.value) == (
        f"place.scale: {float(beyond):g} mm per unit makes the tag 20.0 x 12.0 mm, which fits"
        " nowhere in the arm's safe reach inside the area; the largest that fits is"
        f' {largest:.4g} mm per unit (or use "fit")'
    )


def test_fit_keeps_a_thousandth_clear_of_the_largest() -> None:
    fit = place(small_tag(), load_profile(None, AREA))
    assert fit.mm_per_unit == pytest.approx(fit.largest * (1 - 1e-3), rel=1e-12)
    x0, x1, _, _ = fit.box
    assert x1 - x0 == pytest.approx(20.0 * (1 - 1e-3), abs=2e-3)


def test_a_placement_that_leaves_the_reach_is_refused_naming_the_first_sample() -> None:
    """The tag starts 290 mm from the shoulder and its first stroke runs along +x: the first
    sample of the 1 ms grid beyond the arm's reach (l1 + l2 = 300 mm) is named, with its time
    from the plan's start and its position."""
    profile = load_profile()
    tag = small_tag()
    size = 12.0
    placement = Placement(
        np.eye(2) * size, np.array([-30.0, 290.0]), size, (0.0, 0.0, 0.0, 0.0), size
    )
    with pytest.raises(PlacementError) as raised:
        build_program(tag, profile, placement)
    found = re.fullmatch(
        r"plan 0 at t = (\d+\.\d{3}) s: \((-?\d+\.\d\d), (-?\d+\.\d\d)\) mm is out of the arm's"
        r" reach",
        str(raised.value),
    )
    assert found is not None, str(raised.value)
    t, x, y = (float(g) for g in found.groups())
    assert math.hypot(x, y) > 300.0 - 0.01
    # Independently: the tag's own motion on the 1 ms grid from the plan's start (the run's
    # ends are not both in reach, so it is not trimmed), placed; the first sample beyond 300.
    plan = tag.plans[0]
    grid = plan.start + np.arange(0, int(plan.end(tag.size) / 0.001) + 2) * 0.001
    xy, _ = evaluate_plan(plan, grid, tag.size)
    placed = xy * size + [-30.0, 290.0]
    first = int(np.argmax(np.hypot(*placed.T) > 300.0))
    assert first > 0 and t == pytest.approx(grid[first] - plan.start, abs=5e-4)
    assert (x, y) == pytest.approx(tuple(placed[first]), abs=5e-3)


def test_the_safe_workspace_holds_its_edges_and_not_a_hair_beyond() -> None:
    """Each edge of the paper less its margin, and the outer reach circle less the reach
    margin, is inside (with the checks' 1e-6 mm of slack for rounding); the next float beyond
    is not."""
    profile = load_profile()
    m, r = 10.0 - 1e-6, 5.0 - 1e-6
    x_min, x_max, y_min, y_max = profile.area
    edges = {
        "left": ([x_min + m, 150.0], [-1.0, 0.0]),
        "right": ([x_max - m, 150.0], [1.0, 0.0]),
        "top": ([0.0, y_max - m], [0.0, 1.0]),
        "bottom": ([-100.0, y_min + m], [0.0, -1.0]),
    }
    for name, (point, out) in edges.items():
        p = np.array(point)
        beyond = np.nextafter(p, p + 1e3 * np.array(out))
        assert bool(safe(p, profile)) and not bool(safe(beyond, profile)), name
    wide = load_profile(None, ["area.y_max=400", "area.y_min=-100", "area.x_min=-400"])
    outer = np.array([-(300.0 - r), 0.0])  # on the shoulder's -x axis, within its -30..210°
    assert bool(safe(outer, wide))
    assert not bool(safe(np.nextafter(outer, -np.inf), wide))


def test_the_inner_reach_circle_keeps_its_margin_and_not_a_hair_less() -> None:
    """Links of 150 and 100 mm leave a hole of 50 mm radius round the shoulder; with an elbow
    that folds to 175° the reach margin (5 mm) is what keeps the pen out of it."""
    folded = load_profile(
        None,
        ["arm.l2=100", "elbow.max_deg=175", "area.y_max=400", "area.y_min=-100", "area.x_min=-400"],
    )
    inner = np.array([-(55.0 - 1e-6), 0.0])  # on the shoulder's -x axis, within its -30..210°
    assert bool(safe(inner, folded))
    assert not bool(safe(np.nextafter(inner, np.inf), folded))


@pytest.mark.parametrize("elbow_min", [100, 120])
def test_fit_and_the_largest_scale_are_placed_where_the_area_grid_finds_no_room(elbow_min) -> None:
    """An elbow that cannot fold past 100 or 120° leaves a small region where the largest boxes
    fit, between the points of the area's grid: "fit" and the largest scale itself are still
    placed (inside the arm's safe reach), not refused as fitting nowhere; beyond it, refused."""
    limits = [f"elbow.min_deg={elbow_min}"]
    fit = place(hook_from_its_end(), load_profile(None, limits))
    assert fit.mm_per_unit == pytest.approx(fit.largest * (1 - 1e-3), rel=1e-12)
    largest = float(fit.largest)
    at = place(hook_from_its_end(), load_profile(None, [*limits, f"place.scale={largest!r}"]))
    assert at.mm_per_unit == largest
    x0, x1, y0, y1 = at.box
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
    assert safe(corners, load_profile(None, limits)).all()
    with pytest.raises(PlacementError, match="fits nowhere"):
        place(
            hook_from_its_end(),
            load_profile(None, [*limits, f"place.scale={largest * (1 + 1e-6)!r}"]),
        )
