"""Placement in the safe workspace, runs trimmed to one tick and retimed to the joint limits (per
run or uniform), pen moves and travel at machine speed, refusals up front."""

from __future__ import annotations

import functools
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

import tagbot
from tagbot.arm import Arm, build_program, check_program, load_profile, place
from tagbot.arm.kinematics import RAD_PER_TICK
from tagbot.arm.place import FINE_STEP, approach, safe, time_at_ends
from tagbot.arm.run import prepare
from tagbot.errors import PlacementError
from tagbot.metrics import compare_execution, densify, executed_runs
from tagbot.model import Plan, Tag, evaluate_plan
from tagbot.model.motion import sample_plan
from tagbot.source import load_tag

from .conftest import small_tag, two_plan_tag

EXAMPLES = Path(tagbot.__file__).parent / "examples"


@functools.cache
def example(name: str) -> Tag:
    """A shipped example: a plan file, or a capture fitted once (``dusttag-142.json``)."""
    return load_tag(str(EXAMPLES / name))


def _pen_down_points(tag, placement) -> np.ndarray:
    points = np.concatenate([sample_plan(tag, k, FINE_STEP)[1] for k in range(len(tag.plans))])
    return points @ placement.matrix.T + placement.offset


def test_fit_is_the_largest_safe_box_aspect_kept() -> None:
    profile = load_profile()
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    placed = place(tag, profile)
    assert np.allclose(placed.matrix, placed.mm_per_unit * np.eye(2))  # no rotation, no mirror
    points = _pen_down_points(tag, placed)
    assert safe(points, profile).all()
    # The box itself (not only the tag) is in the safe workspace, and 1 % larger fits nowhere.
    x0, x1, y0, y1 = placed.box
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1], [(x0 + x1) / 2, y0]])
    assert safe(corners, profile).all()
    bigger = load_profile(None, [f"place.scale={placed.largest * 1.01}"])
    with pytest.raises(PlacementError, match="fits nowhere"):
        place(tag, bigger)


def test_the_fitted_box_holds_the_motion_between_its_samples() -> None:
    # An arc bowing up to the top of the area, its apex between two 1 ms samples: every instant
    # of the motion is in the safe workspace, not only the samples the placement looked at.
    profile = load_profile()
    plan = Plan(
        targets=[[0.0, 0.0], [10.0, 0.0], [10.0, -6.0]],
        dt=[0.0, 0.1],
        mu=[math.log(0.2)] * 2,
        sigma=[0.25] * 2,
        phi1=[0.5, 0.0],
        phi2=[-0.5, 0.0],
    )
    tag = Tag(plans=(plan,))
    placed = place(tag, profile)
    dense = sample_plan(tag, 0, 1e-5)[1] @ placed.matrix.T + placed.offset
    assert safe(dense, profile).all()
    assert dense[:, 1].max() > profile["area.y_max"] - profile["area.margin"] - 0.05  # at the top
    for rate in (100, 200, 500):
        build_program(tag, load_profile(None, [f"motion.rate={rate}"]))


def test_explicit_scale_and_rotation() -> None:
    profile = load_profile(None, ["place.scale=3", "place.rotation=90"])
    placed = place(small_tag(), profile)
    assert placed.mm_per_unit == 3.0
    assert np.allclose(placed.matrix, [[0.0, -3.0], [3.0, 0.0]], atol=1e-12)
    x0, x1, y0, y1 = placed.box
    assert x1 - x0 == pytest.approx(3 * 6.0, abs=0.1)  # the 6-unit rise now runs along -x
    assert y1 - y0 == pytest.approx(3 * 10.0, abs=0.1)


def test_too_large_a_scale_is_refused_naming_the_largest() -> None:
    profile = load_profile(None, ["place.scale=100"])
    with pytest.raises(PlacementError) as raised:
        place(small_tag(), profile)
    message = str(raised.value)
    assert message.startswith("place.scale: 100 mm per unit makes the tag 1000.0 x 600.0 mm")
    assert "the largest that fits is" in message


def test_unreachable_area_is_refused() -> None:
    profile = load_profile(None, ["area.x_min=400", "area.x_max=600"])
    with pytest.raises(PlacementError) as refused:
        place(small_tag(), profile)
    assert str(refused.value) == (
        "placement: no part of the area (area.*) is in the arm's safe reach"
        " (check arm.base_x/base_y, the link lengths and the joint limits)"
    )


def test_an_arm_and_paper_moved_together_place_the_tag_moved_with_them() -> None:
    """The shoulder axis (arm.base_x) and the paper (area.x_min/x_max) 60 mm to the right: the
    reach is measured from where the shoulder is, so the tag is placed at the same size,
    60 mm to the right."""
    here = place(small_tag(), load_profile())
    moved = ["arm.base_x=60", "area.x_min=-88.5", "area.x_max=208.5"]
    there = place(small_tag(), load_profile(None, moved))
    assert there.mm_per_unit == pytest.approx(here.mm_per_unit, rel=1e-9)
    np.testing.assert_allclose(there.offset, here.offset + np.array([60.0, 0.0]), atol=1e-9)


def test_joint_limits_shrink_the_workspace() -> None:
    wide = place(small_tag(), load_profile())
    narrow_profile = load_profile(None, ["shoulder.min_deg=80", "shoulder.max_deg=100"])
    narrow = place(small_tag(), narrow_profile)
    assert narrow.mm_per_unit < 0.5 * wide.mm_per_unit
    arm = Arm.from_profile(narrow_profile)
    q = arm.ik(_pen_down_points(small_tag(), narrow))
    assert np.all(np.degrees(q[:, 0]) >= 80 - 1e-6) and np.all(np.degrees(q[:, 0]) <= 100 + 1e-6)
    with pytest.raises(PlacementError, match="fits nowhere"):
        place(
            small_tag(),
            load_profile(
                None,
                ["shoulder.min_deg=80", "shoulder.max_deg=100", f"place.scale={wide.mm_per_unit}"],
            ),
        )


def _run_rows(program, k: int) -> np.ndarray:
    """Rows of run ``k``, from its first sample (the pen just down) to its last."""
    _, _, first, stop = next(seg for seg in program.segments if seg[:2] == ("draw", k))
    rows = np.arange(first, stop)
    assert np.array_equal(rows, np.flatnonzero(program.setpoints.plan == k))
    return rows


def _demand(program, rows: np.ndarray, profile) -> float:
    """The largest joint speed or √acceleration ratio over ``rows`` (standing still around)."""
    T = program.setpoints.period
    worst = 0.0
    for i, joint in enumerate(profile.joints):
        a = program.angles[np.concatenate([rows[:1], rows, rows[-1:]]), i]
        worst = max(worst, np.max(np.abs(np.diff(a))) / T / joint.max_speed)
        worst = max(worst, math.sqrt(np.max(np.abs(np.diff(a, 2))) / T**2 / joint.max_acceleration))
    return float(worst)


@pytest.mark.parametrize("mode", ["run", "uniform"])
@pytest.mark.parametrize("rate", [100, 200, 500])
def test_retiming_keeps_joint_limits_and_the_lognormal_shape(rate: int, mode: str) -> None:
    profile = load_profile(
        None,
        [
            f"motion.rate={rate}",
            "shoulder.max_speed=90",
            f"motion.time_scale={mode}",
            "motion.max_deviation=0",  # the joint limits alone (the tracking bound: below)
        ],
    )
    tag = tagbot.load_plan(EXAMPLES / "cae.json")
    program = build_program(tag, profile)
    check_program(program, profile)
    sp = program.setpoints
    assert sp.period == pytest.approx(1 / rate) and np.allclose(np.diff(sp.t), 1 / rate)
    assert len(sp.run_scales) == len(sp.run_windows) == len(tag.plans)
    assert sp.time_scale == max(sp.run_scales) and min(sp.run_scales) >= 1.0
    for i, joint in enumerate(profile.joints):
        assert np.max(np.abs(np.diff(program.angles[:, i]))) * rate <= joint.max_speed * (1 + 1e-6)
        acc = np.abs(np.diff(program.angles[:, i], 2)) * rate**2
        assert acc.max() <= joint.max_acceleration * (1 + 1e-6)
    if mode == "uniform":
        assert len(set(sp.run_scales)) == 1
        # One scale, no larger than needed: the run asking most (nearly) reaches a limit.
        assert max(_demand(program, _run_rows(program, k), profile) for k in range(3)) > 0.98
    else:
        assert len(set(sp.run_scales)) > 1
    for k, plan in enumerate(tag.plans):
        rows = _run_rows(program, k)
        s, (start, end) = sp.run_scales[k], sp.run_windows[k]
        if mode == "run" and s > 1.0:
            # Each run slowed only as much as it needs: a limit is (nearly) reached in it.
            assert 0.98 < _demand(program, rows, profile) <= 1.0 + 1e-6
        # The samples are the tag's own motion from the window's start, slowed down by s_k.
        tau = np.arange(len(rows)) / rate / s
        assert start + tau[-1] >= end - 1e-9 and start + tau[-2] < end
        xy, v = evaluate_plan(plan, start + tau, tag.size)
        placed = xy @ sp.placement.matrix.T + sp.placement.offset
        assert np.allclose(placed, sp.xy[rows], atol=1e-9)
        assert np.allclose(v[1:] @ sp.placement.matrix.T / s, sp.v[rows[1:]], atol=1e-9)


def test_per_run_scales_make_the_job_faster_on_the_same_path() -> None:
    tag = example("dusttag-142.json")
    run = build_program(tag, load_profile())
    uniform = build_program(tag, load_profile(None, ["motion.time_scale=uniform"]))
    arm = Arm.from_profile(load_profile())
    assert run.setpoints.time_scale == pytest.approx(uniform.setpoints.time_scale)
    assert run.setpoints.run_windows == uniform.setpoints.run_windows
    saved = 0.0
    for k, s_uniform in enumerate(uniform.setpoints.run_scales):
        s_run = run.setpoints.run_scales[k]
        assert 1.0 <= s_run <= s_uniform * (1 + 1e-9)
        n_run, n_uniform = len(_run_rows(run, k)), len(_run_rows(uniform, k))
        clock = run.setpoints.run_clocks[k]  # eased where the writer touched down moving
        assert (clock.on, clock.off) == run.setpoints.run_windows[k]
        assert n_run - 1 == math.ceil(clock.duration * s_run / 0.01 - 1e-9)
        saved += (n_uniform - n_run) * 0.01
        # Same path (each run is p(start_k + τ/s_k), tested above), from the same start, to the
        # same end within a tick (the last sample is at or just past the window's end).
        ends = [program.setpoints.xy[_run_rows(program, k)[[0, -1]]] for program in (run, uniform)]
        assert np.allclose(ends[0][0], ends[1][0], atol=1e-12)
        tick = arm.tip_resolution(run.angles[_run_rows(run, k)[-1]])
        assert np.hypot(*(ends[0][1] - ends[1][1])) < tick
    assert saved > 2.0  # seconds: the runs that need no slow-down are drawn at the tag's pace
    assert run.setpoints.duration == pytest.approx(uniform.setpoints.duration - saved, abs=1e-9)


def _path(plan, t0: float, t1: float, placement, size: float) -> float:
    """Length of plan's placed path between tag times t0 and t1, mm (densely sampled)."""
    if t1 <= t0:
        return 0.0
    t = np.linspace(t0, t1, 20001)
    xy = evaluate_plan(plan, t, size)[0] @ placement.matrix.T
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


@pytest.mark.parametrize("name", ["cae.json", "dusttag-142.json", "letter-b.json"])
def test_runs_start_and_end_within_one_tick_of_the_motion(name: str) -> None:
    """Plans drawn from rest to rest (the DustTag capture fitted geometrically)."""
    profile = load_profile()
    tag = example(name)
    if name.endswith("142.json"):
        tag = tagbot.fit(tagbot.load_traces(EXAMPLES / name), timing="ignore")
    program = build_program(tag, profile)
    sp, arm = program.setpoints, Arm.from_profile(profile)
    for k, plan in enumerate(tag.plans):
        start, end = sp.run_windows[k]
        # One tick at the pen where the plan's motion starts and ends.
        ends = plan.targets[[0, -1]] @ sp.placement.matrix.T + sp.placement.offset
        rho = arm.tip_resolution(arm.ik(ends))
        before = _path(plan, plan.start, start, sp.placement, tag.size)
        after = _path(plan, end, plan.end(tag.size), sp.placement, tag.size)
        # Less than one tick at the pen is left out at either end, and (nearly) all of it.
        assert 0.8 * rho[0] < before <= rho[0] and 0.8 * rho[1] < after <= rho[1]
    whole = build_program(tag, load_profile(None, ["motion.trim_ticks=0"]))
    assert whole.setpoints.run_windows == tuple(
        (plan.start, plan.end(tag.size)) for plan in tag.plans
    )
    # The pen no longer rests where the lognormal motion starts and ends ...
    resting, drawing = time_at_ends(program, profile, tag)
    before_resting, before_drawing = time_at_ends(whole, profile, tag)
    assert before_resting / before_drawing > 0.25 and resting / drawing < 0.02
    # ... nor near the drawn run's own ends (the last tick of a lognormal tail is slow).
    near, _ = time_at_ends(program, profile)
    assert near / drawing < 0.08 and near < before_resting / 4
    assert drawing < before_drawing - (before_resting - near) * 0.9


def test_pen_moves_and_travel_are_not_stretched(profile) -> None:
    tag = two_plan_tag()
    quick = Tag(
        plans=tuple(
            Plan(
                p.targets, p.dt / 3, p.mu - math.log(3), p.sigma, p.phi1, p.phi2, start=p.start / 3
            )
            for p in tag.plans
        )
    )
    late = Tag(plans=(tag.plans[0], tag.plans[1].at(tag.plans[1].start + 2.0)))
    slow, fast = build_program(tag, profile), build_program(quick, profile)
    assert fast.setpoints.time_scale > 1.5 * slow.setpoints.time_scale
    assert np.array_equal(build_program(late, profile).joints, slow.joints)
    moves = math.ceil(profile["pen.move_time"] / profile.period - 1e-9)
    for program in (slow, fast):
        lengths = [(kind, stop - first) for kind, _, first, stop in program.segments]
        # Down: the pen reaches the paper on the run's first sample; up: from the run's last.
        assert [n for kind, n in lengths if kind == "pen"] == [moves - 1, moves] * 2
    travel = [(kind, stop - first) for kind, _, first, stop in slow.segments if kind != "draw"]
    assert travel == [
        (kind, stop - first) for kind, _, first, stop in fast.segments if kind != "draw"
    ]


def _drawn_deviation(job, out) -> np.ndarray:
    """Per run, the largest distance (mm) of the simulator's pen-down trace from the planned
    path (both directions), drawn through the back end in simulated time."""
    run = job.run(out)
    assert run.error is None
    comparison = compare_execution(run.planned_runs, run.executed, plans=run.plans)
    assert comparison.executed_runs == comparison.planned_runs
    deviation = []
    for (_, xy), executed in zip(run.planned_runs, executed_runs(run.executed), strict=True):
        there = cKDTree(densify(xy, 0.005)).query(executed[:, 1:3])[0]
        back = cKDTree(densify(executed[:, 1:3], 0.005)).query(xy)[0]
        deviation.append(max(there.max(), back.max()))
    return np.array(deviation)


def test_runs_are_slowed_until_the_servos_follow_within_the_tolerance(tmp_path) -> None:
    cae = example("cae.json")
    tag = Tag(plans=(cae.plans[0], cae.plans[2]))
    bounded = prepare(tag)
    free = prepare(tag, overrides=("motion.max_deviation=0",))
    tolerance = bounded.profile["motion.max_deviation"]
    predicted, loose = bounded.program.setpoints.run_tracking, free.program.setpoints.run_tracking
    assert max(predicted) <= tolerance and max(loose) > 1.5 * tolerance
    for k in range(2):
        s, s_free = bounded.program.setpoints.run_scales[k], free.program.setpoints.run_scales[k]
        # Slowed only where the lag asks for it, and then (nearly) to the tolerance.
        assert s >= s_free
        if s > s_free * 1.01:
            assert predicted[k] > 0.8 * tolerance
    # The bound never refuses a tag: it slows a run down to motion.max_time_scale at most.
    capped = prepare(tag, overrides=("motion.max_time_scale=1.3",)).program.setpoints
    assert max(capped.run_scales) == pytest.approx(1.3) and max(capped.run_tracking) > tolerance
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    measured, measured_free = (
        _drawn_deviation(bounded, tmp_path / "a"),
        _drawn_deviation(free, tmp_path / "b"),
    )
    # The simulator's servos are the model, plus the goals' rounding: at most ½ tick on each
    # joint, at the pen ½·tick·(|J·e1| + |J·e2|) = ½·tick·(r + l2), r from the shoulder.
    sp, arm = bounded.program.setpoints, Arm.from_profile(bounded.profile)
    rounding = []
    for k in range(2):
        r = np.hypot(*(sp.xy[sp.plan == k] - [arm.base_x, arm.base_y]).T).max()
        rounding.append(0.5 * RAD_PER_TICK * (r + arm.l2))
    assert np.all(measured <= np.array(predicted) + np.array(rounding))
    assert np.all(measured_free >= 0.8 * np.array(loose))
    assert measured.max() < 0.3 < measured_free.max()


def test_a_dot_is_drawn_whole() -> None:
    profile = load_profile(None, ["place.scale=8"])
    tag = Tag(plans=(small_tag(0.005).plans[0],))  # 0.1 mm of path at 8 mm per unit
    program = build_program(tag, profile)
    plan = tag.plans[0]
    assert program.setpoints.run_windows == ((plan.start, plan.end(tag.size)),)
    assert np.count_nonzero(program.setpoints.plan == 0) > 10


def test_branch_is_kept_and_nothing_flips() -> None:
    for branch in ("positive", "negative"):
        overrides = [f"arm.elbow={branch}"]
        if branch == "negative":
            overrides += ["elbow.min_deg=-160", "elbow.max_deg=-10", "motion.park_elbow=-135"]
            overrides += ["shoulder.min_deg=-20", "shoulder.max_deg=220", "motion.park_shoulder=90"]
        profile = load_profile(None, overrides)
        program = build_program(tagbot.load_plan(EXAMPLES / "cae.json"), profile)
        elbow = program.angles[:, 1]
        assert np.all(np.sign(elbow) == (1 if branch == "positive" else -1))
        # No jumps: at most a joint speed limit's worth per tick.
        assert np.max(np.abs(np.diff(program.angles, axis=0))) < math.radians(180) / 100 * 1.001
        arm = Arm.from_profile(profile)
        down = program.setpoints.pen
        assert np.allclose(arm.fk(program.angles[down]), program.setpoints.xy[down], atol=1e-9)


def test_program_layout_and_pen(profile) -> None:
    program = build_program(two_plan_tag(), profile)
    kinds = [kind for kind, *_ in program.segments]
    assert kinds == ["travel", "pen", "draw", "pen", "travel", "pen", "draw", "pen", "park"]
    goals = program.goals
    assert goals[0, 2] == profile["pen.up"] and goals[-1, 2] == profile["pen.up"]
    sp = program.setpoints
    assert set(np.unique(sp.plan)) == {-1, 0, 1}
    assert np.all(goals[sp.pen, 2] == profile["pen.down"])
    park = np.array(profile.park)
    assert np.allclose(program.angles[0], park) and np.allclose(program.angles[-1], park)
    assert program.joints.shape == (len(sp), 4)
    assert program.describe(program.segments[2][2]) == "plan 0"


def test_a_jobs_planned_timeline_is_its_programs_setpoints_pen_down_1_up_0() -> None:
    """The job's planned timeline (the run folder's motion.csv) is its program's setpoints in
    mm, the speed their velocity's norm and the pen 1 down, 0 up, as int8 like every motion
    table's."""
    job = prepare(two_plan_tag())
    planned, sp = job.planned, job.program.setpoints
    np.testing.assert_array_equal(planned.t, sp.t)
    np.testing.assert_array_equal(planned.xy, sp.xy)
    np.testing.assert_array_equal(planned.speed, np.hypot(sp.v[:, 0], sp.v[:, 1]))
    assert planned.pen.dtype == np.int8
    assert planned.pen.tolist() == [1 if down else 0 for down in sp.pen.tolist()]


def test_joint_speed_refused_before_anything() -> None:
    profile = load_profile(None, ["shoulder.max_speed=5", "motion.max_time_scale=2"])
    with pytest.raises(PlacementError) as raised:
        build_program(small_tag(), profile)
    message = str(raised.value)
    assert "must be slowed down" in message and "shoulder.max_speed" in message
    assert "motion.max_time_scale = 2" in message


def test_check_program_names_tick_and_limit(profile) -> None:
    program = build_program(small_tag(), profile)
    k = next(first for kind, _, first, _ in program.segments if kind == "draw") + 5
    bad = program.angles.copy()
    bad[k:, 1] -= math.radians(5)  # a jump of the elbow: 500°/s for one tick
    with pytest.raises(PlacementError) as raised:
        check_program(replace(program, angles=bad), profile)
    # 5° in one tick is 500°/s, give or take the run's own motion there.
    assert re.match(
        rf"tick {k} \(t = {k / 100:.3f} s, plan 0\): elbow speed (4[5-9]|5[0-4])\d\.\d",
        str(raised.value),
    )
    assert str(raised.value).endswith("above elbow.max_speed = 180°/s")
    too_far = program.angles.copy()
    too_far[k:, 1] = math.radians(161)
    with pytest.raises(PlacementError, match=r"elbow at 161.00° beyond elbow.max_deg = 160° by 1"):
        check_program(replace(program, angles=too_far), profile)
    off = program.setpoints.xy.copy()
    off[program.setpoints.pen] += [0.0, 500.0]
    with pytest.raises(PlacementError, match="outside the safe reach"):
        check_program(replace(program, setpoints=replace(program.setpoints, xy=off)), profile)
    # a servo's range ends, 0 and 4095 ticks, are goals; a tick beyond either is not
    where = re.escape(f"tick {k} (t = {k / 100:.3f} s, plan 0)")
    for end, beyond in ((0, -1), (4095, 4096)):
        goals = program.joints.copy()
        goals[k, 3] = end
        check_program(replace(program, joints=goals), profile)
        goals[k, 3] = beyond
        with pytest.raises(
            PlacementError, match=rf"^{where}: pen goal {beyond} ticks is outside 0\.\.4095$"
        ):
            check_program(replace(program, joints=goals), profile)


def test_approach_time_respects_the_limits(profile) -> None:
    present = np.array([2048, 2048, 0])
    goals, duration = approach(present, profile)
    elbow = profile.joint("elbow")
    assert goals.tolist() == [2048, 2048 + 1536, profile["pen.up"]]
    move = math.radians(135)  # the elbow from 0° to the park pose's 135°
    assert duration == pytest.approx(
        max(4 * move / (3 * elbow.max_speed), math.sqrt(16 * move / (3 * elbow.max_acceleration)))
    )
