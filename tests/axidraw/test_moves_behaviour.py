"""The AxiDraw job as a user sees it: travel times against the trapezoid, the refusal of a move
past one step per tick at its exact boundary, pen lines, parking, the job's clock and errors."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tagbot
from firmware_protocols.ebb.motion import (
    ACCUMULATOR_STEP,
    TICK_HZ,
    AxisStart,
    Move,
    axis_final,
    execute,
)
from tagbot.axidraw.moves import (
    CRAWL,
    SETTLE,
    SPEED_MARGIN_DB,
    _axis,
    _check_rates,
    _db,
    _lm_rate,
    _travel_moves,
    build_job,
    fifo_depth,
    run_reference,
    steps_to_xy,
)
from tagbot.axidraw.profile import MOTOR_AXES, load_profile
from tagbot.errors import PlacementError
from tagbot.io.planfile import load_plan
from tagbot.model import Tag
from tagbot.plotter.place import place

from .test_short_runs import _hook

MAX_RATE = 2**31 - 1  # one step per tick
CAE = Path(tagbot.__file__).parent / "examples" / "cae.json"


def run_moves(moves, accumulators=(0, 0)):
    """Each move executed in turn: per move its ticks (relative to where it starts)."""
    out, here = [], np.zeros(2, dtype=np.int64)
    for move in moves:
        relative, accumulators = execute(move, accumulators)
        out.append(relative + here)
        here = out[-1][-1]
    return out, accumulators


def trapezoid(steps: float, vmax: float, amax: float, v0: float) -> float:
    """s to cover ``steps`` from and to ``v0`` at most ``vmax`` steps/s, ``amax`` steps/s²."""
    ramp = (vmax * vmax - v0 * v0) / (2 * amax)
    if steps >= 2 * ramp:
        return 2 * (vmax - v0) / amax + (steps - 2 * ramp) / vmax
    return 2 * (math.sqrt(steps * amax + v0 * v0) - v0) / amax


@pytest.mark.parametrize(
    "delta",
    [(20, 7), (12, 12), (200, -50), (1000, 1), (-5000, 3000), (3, -6000), (40000, -40000)],
)
def test_travel_ends_exactly_and_takes_the_trapezoids_time(delta):
    profile = load_profile()
    k = profile.steps_per_mm
    vmax = profile["limits.travel_speed"] * k
    amax = profile["limits.travel_acceleration"] * k
    moves = _travel_moves(delta, profile)
    assert all(m.command == "LM" and m.clear == 0 for m in moves)
    ticks, _ = run_moves(moves)
    assert tuple(ticks[-1][-1]) == delta  # step-exact on both motors
    longest = max(abs(d) for d in delta)
    expected = trapezoid(longest, vmax, amax, amax * CRAWL)
    took = sum(len(t) for t in ticks) / TICK_HZ
    assert took == pytest.approx(expected, rel=0.015, abs=3 / TICK_HZ)
    # Accelerate, (cruise,) decelerate; each phase's motors finish within 2 % of each other.
    assert len(moves) == (3 if longest >= 2 * (vmax**2 - (amax * CRAWL) ** 2) / (2 * amax) else 2)
    for move, moved in zip(moves, ticks, strict=True):
        finished = [
            int(np.flatnonzero(moved[:, i] != moved[-1, i]).max(initial=-1)) + 2
            for i in (0, 1)
            if move.steps[i]
        ]
        assert max(finished) - min(finished) <= 0.02 * len(moved) + 2, move
    # Never faster than the travel speed along the longer motor axis (10 ms windows).
    path = np.concatenate(ticks)[:, int(np.argmax(np.abs(delta)))]
    window = TICK_HZ // 100
    if len(path) > window:
        fastest = np.abs(path[window:] - path[:-window]).max() / (window / TICK_HZ)
        assert fastest <= vmax * 1.01


@pytest.mark.parametrize("delta", [(1, 0), (0, 1), (1, 1), (-1, 1)])
def test_a_travel_of_a_step_or_two_is_one_move_at_the_crawl(delta):
    profile = load_profile()
    k = profile.steps_per_mm
    crawl = profile["limits.travel_acceleration"] * k * CRAWL  # steps/s
    moves = _travel_moves(delta, profile)
    assert len(moves) == 1
    (move,) = moves
    unit = ACCUMULATOR_STEP / TICK_HZ
    assert move.accel == (0, 0)
    assert move.steps == delta
    for steps, rate in zip(move.steps, move.rate, strict=True):
        assert rate == (round(crawl * unit) if steps else 0)
    ticks, _ = run_moves(moves)
    assert tuple(ticks[-1][-1]) == delta


def test_no_travel_when_already_there():
    assert _travel_moves((0, 0), load_profile()) == []


def test_a_travel_is_slower_on_a_slower_machine():
    fast, slow = load_profile(), load_profile(overrides=["limits.travel_speed=50"])
    calm = load_profile(overrides=["limits.travel_acceleration=300"])

    def took(profile):
        return sum(len(t) for t in run_moves(_travel_moves((-8000, 2000), profile))[0]) / TICK_HZ

    k = fast.steps_per_mm
    for profile in (fast, slow, calm):
        vmax = profile["limits.travel_speed"] * k
        amax = profile["limits.travel_acceleration"] * k
        assert took(profile) == pytest.approx(trapezoid(8000, vmax, amax, amax * CRAWL), rel=0.015)


def lt(rate: int, accel: int = 0, ticks: int = 10, jerk: int = 0) -> Move:
    command = "T3" if jerk else "LT"
    return Move(command, (rate, 0), (accel, 0), (jerk, 0), ticks=ticks)  # type: ignore[arg-type]


def refused(move: Move) -> str | None:
    try:
        _check_rates(move)
    except PlacementError as e:
        return str(e)
    return None


def test_a_move_at_one_step_per_tick_is_kept_and_one_unit_more_refused():
    # LT: the loaded rate is Rate - Accel/2; tick k adds r + a·k. Accel 2 over 10 ticks: the
    # last tick adds Rate - 1 + 20.
    assert refused(lt(MAX_RATE - 19, 2)) is None
    assert refused(lt(MAX_RATE - 18, 2)) == (
        "motion: a drawing move needs 25000 steps/s on a motor, beyond the EBB's 25000"
        " (lower limits.draw_speed)"
    )
    # The first tick decides when the rate falls: Rate - 1 + 2 at tick 1 with Accel 2.
    assert refused(lt(MAX_RATE - 1, 2, ticks=1)) is None
    assert refused(lt(MAX_RATE, 2, ticks=1)) is not None
    assert refused(lt(MAX_RATE, -2)) is None  # falling from one step per tick
    # Backwards alike.
    assert refused(lt(-MAX_RATE + 19, -2)) is None and refused(lt(-MAX_RATE + 18, -2)) is not None
    # A parameter itself beyond 32 bits is refused even where the rates stay in range.
    assert refused(lt(-(2**30), MAX_RATE, ticks=1)) is None
    assert refused(lt(-(2**30), MAX_RATE + 1, ticks=1)) is not None


def test_a_t3_whose_rate_peaks_mid_move_is_judged_at_its_peak():
    # T3 with Accel 99 and Jerk -2 over 100 ticks: the loaded accel is 101, the rate
    # r + 100k - k² peaks at tick 50 only (r + 2500; r + 2499 at ticks 49 and 51), above both
    # ends (r + 99, r). Rate = r + int(99/2) - int(-2/6) = r + 49.
    peak_ok = MAX_RATE - 2500 + 49
    assert refused(lt(peak_ok, 99, ticks=100, jerk=-2)) is None
    message = refused(lt(peak_ok + 1, 99, ticks=100, jerk=-2))
    assert message is not None and "25000 steps/s" in message
    # The same from below (a rate most negative mid-move).
    assert refused(lt(-peak_ok, -99, ticks=100, jerk=2)) is None
    assert refused(lt(-peak_ok - 1, -99, ticks=100, jerk=2)) is not None
    # A peak after the move's last tick is not reached: the last tick decides (r + 2400).
    assert refused(lt(peak_ok + 100, 99, ticks=40, jerk=-2)) is None
    assert refused(lt(peak_ok + 101, 99, ticks=40, jerk=-2)) is not None


def test_a_t3_is_judged_at_its_fastest_tick_next_to_its_end():
    """Jerk -100 over 10 ticks, the rate r + 980k - 50k(k+1) cresting between ticks 9 and 10:
    kept when its fastest tick (tick 9, by the firmware's own arithmetic, 20 above tick 10)
    steps once per tick, refused one unit faster."""
    loaded = AxisStart.load(0, 880, -100)
    rates = [loaded.rate_at(k) for k in range(1, 11)]
    assert int(np.argmax(rates)) + 1 == 9 and rates[8] - rates[9] == 20
    rate = MAX_RATE - max(rates)  # tick 9 at one step per tick exactly
    assert refused(lt(rate, 880, ticks=10, jerk=-100)) is None
    assert refused(lt(rate + 1, 880, ticks=10, jerk=-100)) is not None


def test_a_t3_slowing_from_one_step_per_tick_is_kept():
    """Rate at one step per tick, Accel -450, Jerk -1000: the rate's curve crests just before
    tick 1 (59 above the Rate, at "tick 0", which steps nothing); the board (the firmware's
    arithmetic) steps at most once per tick throughout, so the move is kept."""
    move = lt(MAX_RATE, -450, ticks=10, jerk=-1000)
    positions, _ = execute(move)
    assert np.abs(np.diff(positions[:, 0], prepend=0)).max() == 1
    assert refused(move) is None


def test_a_refused_move_names_the_speed_it_needs():
    # 1.5 steps per tick: 37500 steps/s.
    message = refused(lt(3 * 2**30, 0, ticks=5))
    assert message is not None and message.startswith("motion: a drawing move needs 37500 ")


@pytest.mark.parametrize("n", [1, 2, 3])
def test_the_shortest_moves_end_on_their_goal(n):
    # Under one step per tick, as the profile's limits keep every move.
    for accumulator, distance in [(0, 0.6), (2**30, -0.4), (123, 0.5), (2**31 - 1, -0.7)]:
        aim = accumulator + round(distance * n * ACCUMULATOR_STEP)
        goal = math.floor(aim / ACCUMULATOR_STEP)
        rates = (distance * ACCUMULATOR_STEP, distance * ACCUMULATOR_STEP)
        for jerk in (False, True):
            rate, accel, j = _axis(n, accumulator, aim, rates, goal, jerk)
            assert axis_final(n, rate, accel, j, accumulator)[0] == goal
            if n <= 2 or not jerk:
                assert j == 0


@pytest.fixture
def small():
    """cae.json small, parked elsewhere, from a home that is not (0, 0). Built for each test
    (not shared): mutmut runs, for a mutant, the tests that called its function themselves."""
    tag = load_plan(CAE)
    profile = load_profile(overrides=["place.scale=0.3", "motion.park_x=20", "motion.park_y=15"])
    setpoints = place(tag, profile.placement())
    return tag, profile, setpoints, build_job(tag, setpoints, profile, start=(800, -160))


def test_the_job_starts_where_the_motors_are_and_parks_where_asked(small):
    _tag, profile, setpoints, job = small
    k = profile.steps_per_mm
    first = job.entries[0]
    assert first.kind == "travel" and first.start == 0.0
    # Replayed from (800, -160), every entry ends where it says.
    here, accumulators = np.array([800, -160]), (0, 0)
    for entry in job.entries:
        if entry.move is not None:
            relative, accumulators = execute(entry.move, accumulators)
            here = relative[-1] + here
        assert tuple(here) == entry.steps
    park = np.floor(np.array([20 + 15, 20 - 15]) * k + 0.5)
    assert job.entries[-1].steps == tuple(park) and job.entries[-1].kind == "travel"
    assert job.xy(job.entries[-1].steps) == pytest.approx([20.0, 15.0])
    assert np.abs(job.ticks[0] - np.array([800, -160])).max() <= 1  # one tick from home
    # Without parking the job ends as the last run's pen goes up.
    unparked = load_profile(overrides=["place.scale=0.3", "motion.park=false"])
    job2 = build_job(_tag, setpoints, unparked)
    assert job2.entries[-1].kind == "pen" and not job2.entries[-1].pen
    assert job2.duration == job2.entries[-1].end


def test_each_entry_has_its_run_its_pen_and_its_place_on_the_clock(small):
    _tag, _profile, setpoints, job = small
    kinds = "".join({"travel": "T", "pen": "P", "draw": "D"}[e.kind] for e in job.entries)
    assert re.fullmatch(rf"(T+PD+P){{{len(setpoints.runs)}}}T+", kinds)
    run, down = -1, False
    for before, entry in zip(job.entries, job.entries[1:], strict=False):
        assert entry.start == pytest.approx(before.end, abs=1e-12)
    for entry in job.entries:
        assert entry.end == entry.start + entry.duration
        if entry.kind == "pen":
            down = entry.pen
            run = run + 1 if down else run
            assert entry.run == run
        elif entry.kind == "draw":
            assert entry.pen and entry.run == run
        else:
            assert entry.pen is False and entry.run == -1
    assert job.pen_at == [(e.start, e.pen) for e in job.entries if e.kind == "pen"]
    assert job.duration == job.entries[-1].end
    firsts = [e.start for e in job.entries if e.kind == "draw"]
    assert job.run_start[0] == firsts[0]
    assert job.run_start == [
        next(e.start for e in job.entries if e.kind == "draw" and e.run == r)
        for r in range(len(setpoints.runs))
    ]


def test_every_tick_is_on_the_jobs_clock_and_every_move_states_its_own_error(small):
    _each_tick_on_the_clock_and_each_move_states_its_own_error(*small)


def test_after_a_run_built_again_every_move_still_states_its_own_error():
    """Four fast 0.4 s hooks, 15 mm apart, on 50 ms setpoints: each run has its moves split
    and is built again (the runs before it, and their pen and travel moves, left as they
    were), and every move of every run states its own error."""
    hook = _hook().plans[0]
    hooks = [
        replace(hook, targets=hook.targets + np.array([x, 0.0]), start=i * 1.0)
        for i, x in enumerate((0.0, 15.0, 30.0, 45.0))
    ]
    tag = Tag(plans=tuple(hooks))
    profile = load_profile(overrides=["place.scale=1", "motion.dt=0.05"])
    setpoints = place(tag, profile.placement())
    job = build_job(tag, setpoints, profile)
    assert len(job.runs) == 4
    _each_tick_on_the_clock_and_each_move_states_its_own_error(tag, profile, setpoints, job)


def _each_tick_on_the_clock_and_each_move_states_its_own_error(tag, profile, setpoints, job):
    """Each entry's ticks on the job's clock, ending where it says; each draw move's stated
    error its ticks' largest distance from the plan (0 for the other entries)."""
    k = profile.steps_per_mm
    i = 0
    for index, entry in enumerate(job.entries):
        if entry.move is None:
            assert job.move_error[index] == 0.0
            continue
        n = round(entry.duration * TICK_HZ)
        times = job.tick_time[i : i + n]
        np.testing.assert_allclose(times, entry.start + np.arange(1, n + 1) / TICK_HZ, atol=1e-9)
        assert tuple(job.ticks[i + n - 1]) == entry.steps
        if entry.kind == "travel":
            assert job.move_error[index] == 0.0
        else:
            run = setpoints.runs[entry.run]
            at = run_reference(tag, run, setpoints.matrix, setpoints.offset)
            planned = at(times - job.run_start[entry.run])
            gap = np.hypot(*(steps_to_xy(job.ticks[i : i + n], k) - planned).T)
            assert job.move_error[index] == pytest.approx(gap.max(), abs=1e-9)
        i += n
    assert i == len(job.ticks) == len(job.tick_time)
    for index, (times, xy) in enumerate(job.planned_runs()):
        run = setpoints.runs[index]
        np.testing.assert_array_equal(times, job.run_start[index] + run.t)
        np.testing.assert_array_equal(xy, run.xy)


def test_each_runs_stated_speed_snrs_are_its_plans_speed_over_their_noise(small):
    """A run's steps SNR is its plan's speed energy (motor steps/s over ±10 ms, at every tick
    of the run) over what whole steps cost, 2 x (1/12) / 0.02² a motor per instant, in dB;
    its moves' own figure is the margin or more above it."""
    tag, profile, setpoints, job = small
    k = profile.steps_per_mm
    for index, run in enumerate(setpoints.runs):
        ticks = sum(e.move.ticks for e in job.entries if e.kind == "draw" and e.run == index)
        at = run_reference(tag, run, setpoints.matrix, setpoints.offset)
        plan = at(np.arange(ticks + 1) / TICK_HZ) @ MOTOR_AXES.T * k
        w = round(0.01 * TICK_HZ)
        speed = (plan[2 * w :] - plan[: -2 * w]) / 0.02
        noise = len(speed) * 2 * (2 / 12) / 0.02**2
        expected = 10 * math.log10((speed**2).sum() / noise)
        assert 20.0 < expected < 60.0
        assert job.run_step_snr[index] == pytest.approx(expected, abs=1e-6)
        assert job.run_speed_snr[index] >= job.run_step_snr[index] + SPEED_MARGIN_DB


def test_an_lm_axis_with_steps_to_take_always_has_a_rate():
    """An ``LM`` axis whose share of a long travel phase is a step or two gets the least rate
    that moves (1), not 0 (the board would never finish the move), and not more than it asks;
    an axis with no steps gets 0."""
    assert _lm_rate(0.23, 1) == 1
    assert _lm_rate(1.2, -1) == 1
    assert _lm_rate(1.6, 2) == 2
    assert _lm_rate(5000.4, 0) == 0


def test_a_fifo_one_deep_is_enough_when_two_moves_hold_the_time_ahead():
    """The least depth asked for may be 1 (or 0: the FIFO is at least one deep): two moves of
    0.5 s on the board hold the 0.9 s ahead, so 1 it is."""
    assert fifo_depth([0.5] * 10, 1, 0.9) == 1
    assert fifo_depth([0.5] * 10, 0, 0.9) == 1
    assert fifo_depth([0.5] * 10, 0, 1.2) == 2


def test_fifo_depth_is_the_least_that_holds_the_time_ahead():
    assert fifo_depth([0.025] * 40, 8, 0.2) == 8  # 9 moves of 25 ms: 0.225 s
    assert fifo_depth([0.0125] * 40, 8, 0.2) == 15  # 16 moves of 12.5 ms: 0.2 s
    assert fifo_depth([0.025] * 4, 8, 10.0) == 8  # the whole job is on the board at once
    assert fifo_depth([0.004] * 100, 8, 0.2) == 32  # 33 moves of 4 ms: the deepest there is
    # A short stretch among long moves sets the depth: 9 held, 4 x 12.5 + 5 x 25 ms = 0.175 s;
    # 10 held, 0.2 s.
    assert fifo_depth([0.025] * 20 + [0.0125] * 4 + [0.025] * 20, 8, 0.2) == 9


def test_a_job_shorter_than_the_time_ahead_needs_no_deeper_fifo_than_it_has_moves():
    """Three moves of 0.1 s, 10 s ahead asked: the whole job is on the board at once with a
    FIFO two deep (two queued, one executing), so the least depth asked for it is."""
    assert fifo_depth([0.1] * 3, 2, 10.0) == 2
    assert fifo_depth([0.1] * 3, 1, 10.0) == 2
    assert fifo_depth([0.1] * 4, 1, 10.0) == 3


def test_no_runs_and_no_travel_is_an_empty_job():
    profile = load_profile(overrides=["motion.park=false"])
    tag = load_plan(CAE)
    setpoints = replace(place(tag, load_profile().placement()), runs=())
    job = build_job(tag, setpoints, profile)
    assert job.entries == [] and job.duration == 0.0
    assert job.ticks.shape == (0, 2) and job.tick_time.shape == (0,)
    home = build_job(tag, setpoints, load_profile(), start=(160, 0))
    assert {e.kind for e in home.entries} == {"travel"} and home.entries[-1].steps == (0, 0)


def test_machine_mm_of_motor_steps():
    k = 80.0
    assert steps_to_xy([80, 80], k) == pytest.approx([1.0, 0.0])
    assert steps_to_xy([80, -80], k) == pytest.approx([0.0, 1.0])
    np.testing.assert_allclose(steps_to_xy(np.array([[160, 0], [0, 160]]), k), [[1, 1], [1, -1]])


def test_pen_lines_carry_the_servo_time_and_pin():
    assert SETTLE == 0.002
    tag = load_plan(CAE)
    still = load_profile(overrides=["pen.up=30", "pen.down=30", "pen.pin=2"])
    job = build_job(tag, place(tag, still.placement()), still)
    pens = [e for e in job.entries if e.kind == "pen"]
    # The same height: no travel time, but SP still waits its shortest, 1 ms.
    assert {e.line for e in pens} == {b"SP,0,1,2\r", b"SP,1,1,2\r"}
    assert {e.duration for e in pens} == {0.001}
    slow = load_profile(overrides=["pen.delay_down=0.25"])
    job = build_job(tag, place(tag, slow.placement()), slow)
    down = [e for e in job.entries if e.kind == "pen" and e.pen]
    assert down[0].line == b"SP,0,396,1\r" and down[0].duration == 0.396
    # A pen that waits over half a second: still whole milliseconds of its time (SP,0,746).
    slower = load_profile(overrides=["pen.delay_down=0.6"])
    job = build_job(tag, place(tag, slower.placement()), slower)
    down = [e for e in job.entries if e.kind == "pen" and e.pen]
    assert down[0].line == b"SP,0,746,1\r" and down[0].duration == 0.746


def test_the_jobs_ticks_are_the_boards_from_the_accumulators_em_clears():
    # A crawl of exactly (2**32 - 1) / 3 units a tick (16 667 steps/s, one phase): three ticks
    # end one unit short of two steps, so where each accumulator starts decides tick 3.
    fast = ["limits.travel_acceleration=208333.3333", "limits.travel_speed=208.3333333"]
    profile = load_profile(overrides=fast)
    tag = load_plan(CAE)
    setpoints = replace(place(tag, load_profile().placement()), runs=())
    rate = 1431655765
    for start, line in [
        ((0, -40), b"LM,0,0,0,1431655765,40,0\r"),
        ((-40, 0), b"LM,1431655765,40,0,0,0,0\r"),
    ]:
        job = build_job(tag, setpoints, profile, start=start)
        (entry,) = job.entries
        assert entry.line == line
        expected = [min(k * rate // ACCUMULATOR_STEP, 40) for k in range(1, len(job.ticks) + 1)]
        moving = int(np.argmin(start))
        assert (job.ticks[:, moving] + 40).tolist() == expected
        assert expected[:4] == [0, 1, 1, 2] and job.ticks[-1].tolist() == [0, 0]


@pytest.mark.parametrize("n", [50, 1250, 2500])
def test_a_t3_from_rest_to_rest_starts_and_ends_at_rest(n):
    # 0.3 steps a tick on average, from and to a standstill: all of it is the jerk's. The rates
    # at the move's ends (ticks 1/2 and n + 1/2) are within 1 step/s of zero.
    distance = 0.3 * n
    aim, goal = round(distance * ACCUMULATOR_STEP), math.floor(distance)
    rate, accel, j = _axis(n, 0, aim, (0.0, 0.0), goal, True)
    r, a = rate - int(accel / 2) + int(j / 6), accel - j
    for k in (0.5, n + 0.5):
        at = r + a * k + j * k * (k + 1) / 2
        assert abs(at) / ACCUMULATOR_STEP * TICK_HZ < 1.0
    assert axis_final(n, rate, accel, j)[0] == goal and j < 0


def test_an_snr_is_its_ratio_in_db_down_to_minus_infinity_at_no_signal():
    """The stated SNRs (``run_*_speed_snr_db``): ``10·log10(signal / noise)``, below 0 dB too
    (a signal weaker than 1, steps²/s², is still a figure), -inf without signal, inf without
    noise (the report writes both as null)."""
    assert _db(0.5, 1.0) == pytest.approx(10 * math.log10(0.5))
    assert _db(1.0, 4.0) == pytest.approx(-6.0206, abs=1e-4)
    assert _db(1000.0, 1.0) == pytest.approx(30.0)
    assert _db(0.0, 1.0) == -math.inf
    assert _db(5.0, 0.0) == math.inf


def test_the_jobs_reference_passes_through_every_setpoint_of_its_run(cae_job):
    """The plan each run's ticks are measured against (run_reference) is the tag as placed: at
    each setpoint's instant it is that setpoint, to float rounding, up to the run's last one
    (where its strokes' windows are the tag's, not those of the plan's own smaller extent)."""
    tag, _profile, setpoints, _job = cae_job
    assert all(np.ptp(p.targets, axis=0).max() < 0.6 * tag.size for p in tag.plans)
    for run in setpoints.runs:
        at = run_reference(tag, run, setpoints.matrix, setpoints.offset)
        np.testing.assert_allclose(at(run.t), run.xy, rtol=0.0, atol=1e-9)


def test_a_run_shorter_than_the_speed_window_is_drawn_with_no_speed_figure():
    """A 12 ms run (shorter than the ±10 ms speed window) still becomes its draw moves, each
    with its own error, and states no speed SNR (inf: nothing to measure it over)."""
    tag = load_plan(CAE)
    profile = load_profile(overrides=["place.scale=0.3", "motion.park=false"])
    setpoints = place(tag, profile.placement())
    run = setpoints.runs[0]
    at = run_reference(tag, run, setpoints.matrix, setpoints.offset)
    t, h = np.array([0.0, 0.012]), 1e-6
    short = replace(run, t=t, xy=at(t), v=(at(t + h) - at(t - h)) / (2 * h))
    job = build_job(tag, replace(setpoints, runs=(short,)), profile)
    draws = [i for i, e in enumerate(job.entries) if e.kind == "draw"]
    assert sum(job.entries[i].duration for i in draws) == pytest.approx(0.012)
    assert all(0.0 < job.move_error[i] < 0.012 for i in draws)
    assert job.run_speed_snr == [math.inf] and job.run_step_snr == [math.inf]
