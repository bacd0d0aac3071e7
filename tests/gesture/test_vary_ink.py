"""Variations of timed plans: the ink follows the rhythm, and the pen lifts keep their durations
(lift-off to touch-down)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tagbot.errors import PlanError
from tagbot.gesture import Variation, vary
from tagbot.gesture.vary import in_order, lifts
from tagbot.model.motion import sample_ink, sample_plan
from tagbot.model.plan import Plan, Tag, random_timed_plan

STEP = 0.0005
"""Seconds between the samples the checks measure paths on."""
TOLERANCE = 2e-3
"""How far (as a fraction of a plan's path) a varied touch-down or lift-off may be from the
original's: the polylines' and the samples' error at :data:`STEP`, far below a rhythm's effect
(several % of the path)."""


def inked(tag: Tag, k: int) -> tuple[float, float]:
    """Where plan ``k`` touches down and lifts off, as fractions of its path: measured on its
    motion sampled every :data:`STEP` s (polyline lengths), not with the code under test."""
    t, xy, _ = sample_plan(tag, k, STEP)
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    (_, ink, _) = sample_ink(tag, STEP, [k])[0]
    down = tag.plans[k].ink_window(tag.size)[0]
    before = float(np.interp(down, t, path))
    return before / path[-1], (before + float(np.hypot(*np.diff(ink, axis=0).T).sum())) / path[-1]


def timed_tag(seed: int, count: int, windows: list[tuple[float, float]], gaps: list[float]) -> Tag:
    """``count`` random timed plans, plan k inked over the fractions ``windows[k]`` of its
    motion's duration (a lift-off past 1: at the end), ``gaps`` seconds between them."""
    rng = np.random.default_rng(seed)
    plans = []
    for k in range(count):
        p = random_timed_plan(rng)
        duration = p.end(1e3) - p.start
        down, up = windows[k]
        ink = (down * duration, max(up, down + 0.05) * duration)
        plans.append(Plan(p.targets + 150.0 * k, p.dt, p.mu, p.sigma, p.phi1, p.phi2, 0.0, ink))
    return in_order(plans, gaps[: count - 1])


windows = st.tuples(st.floats(0.0, 0.45), st.floats(0.55, 1.1))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    count=st.integers(1, 3),
    windows=st.lists(windows, min_size=3, max_size=3),
    gaps=st.lists(st.floats(0.02, 0.5), min_size=2, max_size=2),
    vary_seed=st.integers(0, 2**32 - 1),
)
def test_variations_ink_the_same_part_of_the_path_and_keep_the_lifts(
    seed: int, count: int, windows: list, gaps: list, vary_seed: int
) -> None:
    tag = timed_tag(seed, count, windows, gaps)
    for instance in vary(tag, 2, vary_seed, Variation(dt=0.25)):
        for k in range(count):
            assert inked(instance, k) == pytest.approx(inked(tag, k), abs=TOLERANCE)
        assert lifts(instance) == pytest.approx(lifts(tag), rel=1e-9, abs=1e-12)


def test_a_varied_rhythm_does_not_ink_the_air() -> None:
    """The issue's case: a plan inked over the middle of its motion inks the same share of its
    path in every variation of its rhythm, as the pen-down samples a picture is painted from
    show; the window kept in seconds (as before) inked up to 9 % more or less of it here."""
    tag = timed_tag(7, 1, [(0.3, 0.6)], [])
    rhythm = Variation(position=0.0, scale=0.0, phi=0.0)
    shares = [drawn_share(instance) for instance in [tag, *vary(tag, 8, 5, rhythm)]]
    assert shares[1:] == pytest.approx([shares[0]] * 8, abs=0.005)
    ink = tag.plans[0].ink
    fixed = [
        drawn_share(Tag((Plan(p.targets, p.dt, p.mu, p.sigma, p.phi1, p.phi2, p.start, ink),)))
        for p in (instance.plans[0] for instance in vary(tag, 8, 5, rhythm))
    ]
    assert max(abs(share / shares[0] - 1.0) for share in fixed) > 0.05


def drawn_share(tag: Tag) -> float:
    """The pen-down path of a one-plan tag's motion (1 ms samples) over its whole path."""
    motion = tag.sample(0.001)
    ((_, rows),) = motion.runs()
    _, xy, _ = sample_plan(tag, 0, 0.001)
    length = lambda xy: float(np.hypot(*np.diff(xy, axis=0).T).sum())  # noqa: E731
    return length(motion.xy[rows]) / length(xy)


def test_plans_without_ink_windows_vary_as_before() -> None:
    """No ink window: lifts run from a motion's end to the next start, as they always did."""
    rng = np.random.default_rng(3)
    a, b = random_timed_plan(rng), random_timed_plan(rng)
    tag = in_order([a, Plan(b.targets + 80.0, b.dt, b.mu, b.sigma, b.phi1, b.phi2)], [0.25])
    assert tag.plans[1].start == pytest.approx(tag.plans[0].end(tag.size) + 0.25, abs=1e-12)
    for instance in vary(tag, 4, 2):
        assert all(p.ink is None for p in instance.plans)
        gap = instance.plans[1].start - instance.plans[0].end(instance.size)
        assert gap == pytest.approx(0.25, rel=1e-9)


def test_in_order_refuses_a_wrong_number_of_lifts() -> None:
    plan = random_timed_plan(np.random.default_rng(1))
    with pytest.raises(PlanError, match="lifts: expected 1"):
        in_order([plan, plan.at(5.0)], [])
    with pytest.raises(PlanError, match="lifts: must be finite"):
        in_order([plan, plan.at(5.0)], [-1.0])
