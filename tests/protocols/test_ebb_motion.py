"""EBB low-level moves (firmware 3.x): firmware_protocols.ebb.motion against two independent
references: a per-tick loop written here from the ISR description (reference "LM", "Methods and
consequences", and the 3.0 source's order: accel += jerk, rate += accel, acc += rate), and the
makers' own ``plotink.ebb_calc`` (closed forms, MIT)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from plotink import ebb_calc

from firmware_protocols.ebb.errors import EBBCommandError, MoveTooLong
from firmware_protocols.ebb.motion import (
    ACCUMULATOR_STEP,
    TICK_HZ,
    AxisStart,
    Move,
    axis_final,
    axis_positions,
    cleared_accumulator,
    execute,
    lm_axis,
    wrap32,
)

INT32 = st.integers(-(2**31), 2**31 - 1)
ACCUMULATOR = st.integers(0, 2**31 - 1)


def i32(value: int) -> int:
    """A signed 32-bit C variable's value."""
    return (value + 2**31) % 2**32 - 2**31


def trunc_div(value: int, divisor: int) -> int:
    """C's integer division."""
    return int(value / divisor) if abs(value) < 2**52 else -(-value // divisor)


def isr(rate, accel, jerk, acc, *, ticks=None, steps=None, clear=False):
    """The stepper ISR, one tick at a time: positions per tick and the final accumulator."""
    if steps is not None and steps < 0:  # LM's legacy sign rule
        steps, rate, accel = -steps, -rate, -accel
    r = i32(i32(rate - trunc_div(accel, 2)) + trunc_div(jerk, 6))
    a = i32(accel - jerk)
    if clear:
        first = i32(r + accel)
        negative = first < 0 or (
            first == 0 and (accel + jerk < 0 or (accel + jerk == 0 and jerk < 0))
        )
        acc = 2**31 - 1 if negative else 0
    position, taken, out = 0, 0, []
    while (ticks is not None and len(out) < ticks) or (steps is not None and taken < steps):
        a = i32(a + jerk)
        r = i32(r + a)
        acc = (acc + r) % 2**32  # unsigned 32-bit
        if acc & 0x80000000:
            acc &= 0x7FFFFFFF
            position += 1 if r >= 0 else -1
            taken += 1
        out.append(position)
    return out, acc


# -- time-limited moves (LT, T3) ----------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(
    ticks=st.integers(1, 300),
    rate=st.one_of(INT32, st.integers(-(2**27), 2**27)),
    accel=st.one_of(st.integers(-(2**20), 2**20), INT32),
    jerk=st.one_of(st.just(0), st.integers(-5000, 5000), INT32),
    acc=ACCUMULATOR,
)
def test_time_limited_axis_matches_the_isr_tick_by_tick(ticks, rate, accel, jerk, acc):
    """Every tick, including rates that wrap around int32 and reverse the motor."""
    positions, final = axis_positions(ticks, rate, accel, jerk, acc)
    expected, expected_acc = isr(rate, accel, jerk, acc, ticks=ticks)
    assert positions.dtype == np.int64
    assert positions.tolist() == expected
    assert final == expected_acc
    assert axis_final(ticks, rate, accel, jerk, acc) == (expected[-1], expected_acc)


@st.composite
def _within_int32(draw):
    """A time-limited axis whose rate stays within int32 (plotink's closed forms assume it)."""
    ticks = draw(st.integers(1, 200_000))
    rate = draw(st.integers(-(2**30), 2**30))
    accel_bound = min(5000, 2**29 // ticks)
    accel = draw(st.integers(-accel_bound, accel_bound))
    jerk_bound = min(3, 2**29 // (ticks * ticks))
    jerk = draw(st.integers(-jerk_bound, jerk_bound))
    return ticks, rate, accel, jerk


@settings(max_examples=200, deadline=None)
@given(case=_within_int32(), acc=st.one_of(st.none(), ACCUMULATOR))
def test_time_limited_final_state_equals_plotink(case, acc):
    """Final step position and accumulator equal ``move_dist_t3``/``move_dist_lt`` exactly."""
    ticks, rate, accel, jerk = case
    start = cleared_accumulator(rate, accel, jerk) if acc is None else acc
    oracle_acc = "clear" if acc is None else acc
    got = axis_final(ticks, rate, accel, jerk, start)
    assert got == ebb_calc.move_dist_t3(ticks, rate, accel, jerk, oracle_acc)
    if jerk == 0:
        assert got == ebb_calc.move_dist_lt(rate, accel, ticks, oracle_acc)
    if ticks <= 20_000:
        positions, final = axis_positions(ticks, rate, accel, jerk, start)
        assert (int(positions[-1]), final) == got


def test_long_move_closed_form_equals_the_cumulative_sums():
    """A 10 s time-limited move: the closed form and the per-tick sums agree to the step."""
    args = (250_000, 40_000_000, -300, 1, 123_456_789)
    positions, final = axis_positions(*args)
    assert axis_final(*args) == (int(positions[-1]), final)
    assert len(positions) == 250_000 == 10 * TICK_HZ


# -- step-limited moves (LM) --------------------------------------------------------------


def _lm_cases():
    """LM axes that finish within some 30 000 ticks (the slow loop must run them)."""
    magnitude = st.integers(2**22, 2**28)
    return st.tuples(
        st.integers(-100, 100).filter(bool),
        st.tuples(st.sampled_from([1, -1]), magnitude).map(lambda t: t[0] * t[1]),
        st.one_of(st.just(0), st.integers(1000, 300_000), st.integers(-300_000, -1000)),
        st.one_of(st.none(), ACCUMULATOR),
    ).filter(lambda c: not (c[0] < 0 and c[1] < 0))


@settings(max_examples=100, deadline=None)
@given(case=_lm_cases())
def test_lm_axis_matches_the_isr_tick_by_tick(case):
    """Positions per tick until the axis has taken its steps, reversals counted as steps."""
    steps, rate, accel, acc = case
    positions, final = lm_axis(steps, rate, accel, acc or 0, clear=acc is None)
    expected, expected_acc = isr(rate, accel, 0, acc or 0, steps=steps, clear=acc is None)
    assert positions.tolist() == expected
    assert final == expected_acc


@settings(max_examples=200, deadline=None)
@given(case=_lm_cases())
def test_lm_axis_equals_plotink_calculate_lm(case):
    """Duration, final position and accumulator equal ``calculate_lm`` exactly.

    plotink treats a reversal within the first two ticks as none (its ``t_rev <= 1`` branch);
    the firmware does reverse there (checked against the ISR loop above), so those are left out.
    """
    steps, rate, accel, acc = case
    r, a = (-rate, -accel) if steps < 0 else (rate, accel)
    assume(not (r and a and (r > 0) != (a > 0) and 0.5 - r / a < 2.5))
    positions, final = lm_axis(steps, rate, accel, acc or 0, clear=acc is None)
    oracle = ebb_calc.calculate_lm(steps, rate, accel, "clear" if acc is None else acc)
    assert (len(positions), int(positions[-1]), final) == oracle


def test_lm_reversal_in_the_first_ticks_follows_the_isr_not_plotink():
    """Rate 51111 on tick 1, then negative: the axis steps backwards (plotink says +154)."""
    positions, final = lm_axis(154, 136_736, -171_249, 2_060_951_929)
    expected, expected_acc = isr(136_736, -171_249, 0, 2_060_951_929, steps=154)
    assert (int(positions[-1]), final, len(positions)) == (expected[-1], expected_acc, 1966)
    assert positions[-1] == -154
    assert ebb_calc.calculate_lm(154, 136_736, -171_249, 2_060_951_929)[1] == 154


def test_lm_that_decelerates_through_zero_reverses_and_counts_every_step():
    positions, _ = lm_axis(30, 8_000_000, -20_000, 0)
    assert max(positions) > positions[-1]  # went forward, then back
    assert int(np.abs(np.diff(positions, prepend=0)).sum()) == 30


def test_lm_axis_that_never_steps_is_refused():
    with pytest.raises(MoveTooLong, match="never completes"):
        lm_axis(10, 0, 0)


def test_negative_steps_flip_rate_and_accel():
    """Cleared, a backward axis starts at 2**31 - 1 and mirrors the forward one exactly."""
    backward, acc_back = lm_axis(-20, 40_000_000, 1000, clear=True)
    forward, acc_fwd = lm_axis(20, 40_000_000, 1000, clear=True)
    assert backward.tolist() == (-forward).tolist()
    assert acc_back == 2**31 - 1 - acc_fwd
    uncleared, _ = lm_axis(-20, 40_000_000, 1000, 0)
    assert uncleared[0] == -1  # from accumulator 0 a backward axis steps on its first tick


# -- whole moves --------------------------------------------------------------------------


def test_documented_lm_example_3_finishes_both_axes_at_10_ms():
    """Reference "LM", example 3: 10 and 2 steps, both done at the end of 10 ms."""
    positions, accumulators = execute(Move("LM", (85899346, 17180814), steps=(10, 2)))
    assert positions.shape == (250, 2)
    assert positions[-1].tolist() == [10, 2]
    assert positions[-2].tolist() == [9, 1]
    assert accumulators == (250 * 85899346 - 10 * 2**31, 250 * 17180814 - 2 * 2**31)


def test_documented_examples_durations_and_distances():
    """Reference "LM" examples 1 and 6, "LT" examples 1 and 3."""
    lm1, _ = execute(Move("LM", (3865471, 0), (1732, 0), steps=(60, 0)))
    assert len(lm1) == 10169  # "T = 10169 intervals"
    lm6, _ = execute(Move("LM", (42950000, 0), (13400, 0), steps=(50, 0)))
    assert round(len(lm6) / TICK_HZ * 1000) == 77  # "The move will take 77 ms"
    lt1, _ = execute(Move("LT", (3865471, 0), (1732, 0), ticks=10169, clear=3))
    assert lt1[-1].tolist() == [60, 0]
    lt3, _ = execute(Move("LT", (17179000, 8592000), (-687, 687), ticks=12500))
    assert lt3[-1].tolist() == [75, 75]  # "The move will cover 75 steps on each axis"


def test_lm_finished_axis_holds_and_accumulators_carry():
    move = Move("LM", (2**30, 2**29), steps=(4, -3), clear=0)
    positions, accumulators = execute(move, (5, 7))
    first, acc1 = lm_axis(4, 2**30, 0, 5)
    second, acc2 = lm_axis(-3, 2**29, 0, 7)
    assert len(positions) == max(len(first), len(second))
    assert positions[: len(first), 0].tolist() == first.tolist()
    assert set(positions[len(first) :, 0].tolist()) <= {4}
    assert positions[-1].tolist() == [4, -3]
    assert accumulators == (acc1, acc2)


@pytest.mark.parametrize(
    ("clear", "expected"), [(0, (11, 22)), (1, (0, 22)), (2, (11, 0)), (3, (0, 0)), (9, (0, 0))]
)
def test_clear_bits_and_the_clamp_above_3(clear, expected):
    """Clear 1/2/3 zero the accumulators of a forward move at load; values above 3 act as 3."""
    move = Move("LT", (1000, 1000), ticks=1, clear=clear)
    _, accumulators = execute(move, (11, 22))
    assert accumulators == (expected[0] + 1000, expected[1] + 1000)


def test_clear_of_a_backward_axis_starts_at_2_31_minus_1():
    assert cleared_accumulator(-5, 0) == 2**31 - 1
    assert cleared_accumulator(0, 0, -6) == 2**31 - 1  # Jerk/6 = -1 is added to Rate at load
    assert cleared_accumulator(5, 0) == 0
    positions, accumulators = execute(Move("LT", (-(2**30), 0), ticks=2, clear=3))
    assert positions[:, 0].tolist() == [0, -1]  # 2**31-1 - 2**30 >= 0, then below 0: one step
    assert accumulators == (2**31 - 1, 0)  # -1 after two ticks, + 2**31 with the step


@pytest.mark.parametrize(
    ("rate", "accel", "jerk", "expected"),
    [(-2, 6, -6, 2**31 - 1), (-3, 6, -5, 0), (0, 0, 0, 0), (3, -6, 0, 2**31 - 1), (-3, 6, 0, 0)],
)
def test_clear_looks_ahead_while_the_rate_is_zero(rate, accel, jerk, expected):
    """First tick's rate zero: the second's sign decides, then the jerk's (firmware order)."""
    assert cleared_accumulator(rate, accel, jerk) == expected
    assert isr(rate, accel, jerk, 12345, ticks=1, clear=True) == isr(
        rate, accel, jerk, expected, ticks=1
    )
    ticks = 50
    assert axis_final(ticks, rate, accel, jerk, expected) == ebb_calc.move_dist_t3(
        ticks, rate, accel, jerk, "clear"
    )


def test_rate_that_wraps_only_mid_move_is_summed_tick_by_tick():
    """The rate peaks above 2**31 - 1 between two in-range ends: the closed form must not apply."""
    args = (200, 0, 2**26, -(2**26) // 100, 0)
    expected, expected_acc = isr(*args[1:4], args[4], ticks=args[0])
    assert axis_final(*args) == (expected[-1], expected_acc)


def test_continuing_a_loaded_axis_is_the_same_sequence():
    start = AxisStart.load(123_456, -789, 35)
    for done, more in [(1, 1), (64, 500), (1000, 3)]:
        assert start.after(done).rate_at(more) == wrap32(start.rate_at(done + more))


def test_lm_longer_than_its_first_guess():
    """A slow start that accelerates hard: several chunks, joined without a seam."""
    positions, final = lm_axis(-90, 5_000_000, 4_000, clear=True)
    expected, expected_acc = isr(5_000_000, 4_000, 0, 0, steps=-90, clear=True)
    assert positions.tolist() == expected
    assert final == expected_acc


def test_lines_are_the_documented_syntax():
    assert Move("LT", (3865471, 0), (1732, 0), ticks=10169, clear=3).line() == (
        b"LT,10169,3865471,1732,0,0,3\r"
    )
    assert (
        Move("LM", (3865471, 0), (1732, 0), steps=(60, 0)).line() == b"LM,3865471,60,1732,0,0,0\r"
    )
    assert Move("T3", (1, 2), (3, 4), (5, 6), ticks=7).line() == b"T3,7,1,3,5,2,4,6\r"


@pytest.mark.parametrize(
    ("move", "limit_checked"),
    [
        (Move("LM", (0, 0), steps=(5, 5)), True),  # no axis can move
        (Move("LM", (7, 0), (1, 0), steps=(0, 0)), True),
        (Move("LT", (7, 7), ticks=0), True),
        (Move("T3", (7, 7), ticks=0), True),
        (Move("LM", (-7, 0), steps=(-5, 0)), False),  # negative Steps with a negative Rate
        (Move("LM", (2**31, 0), steps=(5, 0)), False),  # out of int32
        (Move("LT", (1, 1), ticks=2**32), False),
    ],
)
def test_invalid_moves_get_the_firmware_reply(move, limit_checked):
    with pytest.raises(EBBCommandError) as error:
        execute(move)
    assert error.value.reply == b"!6 Err: Invalid parameter value"
    if limit_checked:
        move.validate(limit_checks=False)  # CU,2,0 lets it through
    else:
        with pytest.raises(EBBCommandError):
            move.validate(limit_checks=False)


def test_constants():
    assert TICK_HZ == 25_000
    assert ACCUMULATOR_STEP == 2**31


def test_zero_interval_move_without_limit_checks_only_clears():
    """``CU,2,0`` lets ``LT,0,...`` through: no tick runs, the clear bits still act at load."""
    positions, accumulators = execute(
        Move("LT", (5, 5), ticks=0, clear=2), (7, 8), limit_checks=False
    )
    assert positions.shape == (0, 2)
    assert accumulators == (7, 0)


# -- edges (issue 34: what a changed line would break) ---------------------------------------


def test_a_long_move_at_the_top_rate_has_its_closed_form():
    """A rate of exactly 2**31 - 1 stays in int32: the closed form holds beyond MAX_TICKS."""
    ticks = 2**24 + 10
    total = (2**31 - 1) * ticks
    assert axis_final(ticks, 2**31 - 1, 0) == (total >> 31, total % 2**31)
    assert axis_final(ticks, -(2**31), 0) == (-ticks, 0)
    with pytest.raises(MoveTooLong, match=r"^16777226 ticks: longer than the 16777216-tick"):
        axis_positions(ticks, 2**31 - 1, 0)


@pytest.mark.parametrize("accumulator", [-1, 2**31])
def test_an_accumulator_out_of_range_is_refused_by_name(accumulator):
    message = rf"^accumulator: must be in \[0, 2\*\*31\), got {accumulator}$"
    with pytest.raises(ValueError, match=message):
        axis_final(10, 1000, 0, 0, accumulator)
    with pytest.raises(ValueError, match=message):
        axis_positions(10, 1000, 0, 0, accumulator)
    with pytest.raises(ValueError, match=message):
        lm_axis(10, 1000, 0, accumulator)
    assert axis_final(1, 0, 0, 0, 2**31 - 1) == (0, 2**31 - 1)


def test_negative_steps_with_a_zero_rate_run_backwards_on_the_accel():
    """Rate 0 is not negative: the legacy rule negates it (and the accel) without ``!6``."""
    backward, _ = lm_axis(-10, 0, 4_000_000, clear=True)
    forward, _ = lm_axis(10, 0, 4_000_000, clear=True)
    assert forward[-1] == 10 and backward.tolist() == (-forward).tolist()
    Move("LM", (0, 0), (4_000_000, 0), steps=(-10, 0)).validate()
    with pytest.raises(EBBCommandError, match=r"negative Steps with a negative Rate"):
        Move("LM", (-1, 0), (4_000_000, 0), steps=(-10, 0)).validate()


def test_an_lm_axis_of_no_steps_keeps_its_rates_sign_and_does_not_run():
    """The legacy sign rule is for negative Steps only: an axis of 0 steps with a negative Rate
    is no ``!6`` and takes no step, and its clear bit loads the accumulator by its own Rate's
    sign (2**31 - 1 for a negative one, 0 for a positive one), as the ISR above does."""
    for rate, cleared in ((1000, 0), (-1000, 2**31 - 1)):
        positions, final = lm_axis(0, rate, 0, 12345, clear=True)
        assert (positions.tolist(), final) == isr(rate, 0, 0, 12345, steps=0, clear=True)
        assert final == cleared
    move = Move("LM", (85899346, -1000), steps=(10, 0))
    move.validate()
    positions, accumulators = execute(move, (0, 777))
    assert positions[-1].tolist() == [10, 0] and not positions[:, 1].any()
    assert accumulators[1] == 777


@pytest.mark.parametrize(
    ("value", "held"),
    [(2**31, -(2**31)), (2**31 - 1, 2**31 - 1), (-(2**31) - 1, 2**31 - 1), (2**32 + 5, 5)],
)
def test_wrap32_is_the_firmwares_signed_32_bit_variable(value, held):
    assert wrap32(value) == held == i32(value)


def test_an_lm_clear_looks_ahead_at_the_accel_alone():
    """``LM`` has no jerk: Rate 1 and Accel -1 give a first tick of rate 0 and a negative second
    one, so its clear loads 2**31 - 1 (a jerk of 1 would have made the second zero)."""
    assert cleared_accumulator(1, -1) == 2**31 - 1
    positions, final = lm_axis(3, 1, -1, 0, clear=True)
    expected, acc = isr(1, -1, 0, 0, steps=3, clear=True)
    assert positions.tolist() == expected and final == acc


def test_no_ticks_is_an_empty_int64_trace():
    positions, final = axis_positions(0, 1000, 0, 0, 77)
    assert positions.dtype == np.int64 and positions.shape == (0,) and final == 77
    positions, final = lm_axis(0, 1000, 0, 77)
    assert positions.dtype == np.int64 and positions.shape == (0,) and final == 77
    out, finals = execute(Move("LT", (5, 5), ticks=0), (3, 4), limit_checks=False)
    assert out.dtype == np.int64 and out.shape == (0, 2) and finals == (3, 4)


def test_parameter_refusals_name_their_reason():
    cases = [
        (Move("LT", (2**31, 0), ticks=10), "a 32-bit signed parameter out of range"),
        (Move("LT", (1, 0), ticks=2**32), "a 32-bit unsigned parameter out of range"),
        (Move("LT", (1, 0), ticks=10, clear=-1), "a 32-bit unsigned parameter out of range"),
        (Move("LM", (-5, 0), steps=(-3, 0)), "LM: negative Steps with a negative Rate"),
        (Move("LM", (0, 5), steps=(3, 0)), "LM: no axis can move"),
        (Move("T3", (1, 0), ticks=0), "T3: Intervals must be > 0"),
    ]
    for move, detail in cases:
        with pytest.raises(EBBCommandError) as caught:
            move.validate()
        assert str(caught.value) == f"!6 Err: Invalid parameter value ({detail})"


def test_an_lm_not_given_one_parameter_per_motor_is_a_programming_error():
    """An LM with one motor's rate, or a third motor's steps, is no command the board could
    answer: a plain ValueError, never the firmware's "no axis can move" reply."""
    for move in (Move("LM", (0,), steps=(0, 0)), Move("LM", (0, 5), steps=(3, 0, 9))):
        with pytest.raises(ValueError, match="zip") as caught:
            move.validate()
        assert not isinstance(caught.value, EBBCommandError)


def test_a_t3_that_wraps_only_at_its_peak_is_summed_tick_by_tick():
    """Loaded rate r + 100k - k² over 100 ticks peaks at tick 50, 3 above int32 (ticks 49-51
    wrap, 48 and 52 do not), while both ends stay inside: the closed form would miss it."""
    r = 2**31 - 1 - 2497
    positions, final = axis_positions(100, r + 49, 99, -2)
    expected, acc = isr(r + 49, 99, -2, 0, ticks=100)
    assert positions.tolist() == expected and final == acc
    assert axis_final(100, r + 49, 99, -2) == (expected[-1], acc)


def test_zero_ticks_leave_the_axis_where_it_was():
    # Even with a first rate beyond int32 (that tick never comes).
    assert axis_final(0, 2**31 - 1, 1000, 0, 5) == (0, 5)
    assert axis_final(-3, 7, 0, 0, 9) == (0, 9)


def test_an_lm_longer_than_the_per_tick_model_is_refused_by_name():
    # Rate 1: one step takes 2**31 ticks.
    with pytest.raises(MoveTooLong, match=r"^LM axis with 1 steps: longer than 16777216 ticks$"):
        lm_axis(1, 1, 0)


@pytest.mark.parametrize(
    ("rate", "accel", "jerk", "ticks"),
    [
        # The rate peaks at tick 9 (a + 10·j < 0: tick 10 is already lower), one above int32.
        (2**31 - 1 - 125, 29, -3, 20),
        (-(2**31) + 125, -29, 3, 20),  # the mirror: a trough one below int32 at tick 9
        (2**31 - 1 - 126, 29, -3, 20),  # one less: the peak is int32's largest, no wrap
    ],
)
def test_a_rate_leaving_int32_only_at_its_extreme_tick_is_caught(rate, accel, jerk, ticks):
    """Whether the rate wraps, against every tick's exact rate: the extreme of the rate's
    parabola may fall on the tick before the rounded vertex."""
    start = AxisStart(rate, accel, jerk)
    exact = [rate + t * accel + jerk * t * (t + 1) // 2 for t in range(1, ticks + 1)]
    assert start.stays_in_int32(ticks) == all(-(2**31) <= r <= 2**31 - 1 for r in exact)


@pytest.mark.parametrize("clear", [0, 3])
def test_a_t3_move_executes_its_jerk_on_both_axes(clear):
    """execute() of a T3 move: each axis, tick by tick, as the ISR runs it with that axis's jerk
    (a jerk of 6000 or -1200 a tick changes the path within 400 ticks)."""
    move = Move("T3", (2**28, -(2**27)), (-5000, 3000), (6000, -1200), ticks=400, clear=clear)
    positions, accumulators = execute(move, (123, 456))
    for axis, acc in enumerate((123, 456)):
        expected, expected_acc = isr(
            move.rate[axis], move.accel[axis], move.jerk[axis], acc, ticks=400, clear=bool(clear)
        )
        assert positions[:, axis].tolist() == expected
        assert accumulators[axis] == expected_acc
    flat, _ = execute(Move("LT", move.rate, move.accel, ticks=400, clear=clear), (123, 456))
    assert flat[-1].tolist() != positions[-1].tolist()
