"""Each run's move length as it needs: moves are shortened where a run's speed changes too fast
for them (their own speed error kept 15 dB under what whole motor steps cost the run), the
figures stated are the moves' exact motion's, and the FIFO deepens so that the board never
holds less drawing ahead than the profile promises (no starvation)."""

from __future__ import annotations

import math
import os
from dataclasses import replace
from itertools import count, pairwise

import numpy as np
import pytest

import tagbot.axidraw.moves as moves
from firmware_protocols.ebb.motion import ACCUMULATOR_STEP, TICK_HZ, AxisStart, execute
from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device
from tagbot.axidraw.machine import prepare
from tagbot.axidraw.moves import SPEED_MARGIN_DB, run_reference
from tagbot.axidraw.profile import MOTOR_AXES
from tagbot.draw import draw
from tagbot.io.planfile import load_plan

from .conftest import CAE, LETTER_B

LONG = ("motion.dt=0.1",)
"""Setpoints every 100 ms: too long for some of cae's runs, not for letter-b's."""

_names = count()


def _lengths(job, run: int) -> list[int]:
    """The ticks of each of ``run``'s moves (their parameters also depend on the accumulators
    an earlier run left)."""
    return [e.move.ticks for e in job.entries if e.kind == "draw" and e.run == run]


def test_moves_are_shortened_in_the_runs_that_need_it_and_only_there(monkeypatch):
    tag = load_plan(CAE)
    with monkeypatch.context() as m:
        m.setattr(moves, "SPEED_MARGIN_DB", -math.inf)  # no run needs shorter moves
        plain = prepare(tag, overrides=LONG).job
    job = prepare(tag, overrides=LONG).job
    needs = [
        snr < step + SPEED_MARGIN_DB
        for snr, step in zip(plain.run_speed_snr, plain.run_step_snr, strict=True)
    ]
    assert any(needs) and not all(needs)
    for run, needed in enumerate(needs):
        assert job.run_speed_snr[run] >= job.run_step_snr[run] + SPEED_MARGIN_DB
        if needed:
            assert len(_lengths(job, run)) > len(_lengths(plain, run))
            assert min(_lengths(job, run)) < min(_lengths(plain, run)[1:])
        else:
            assert _lengths(job, run) == _lengths(plain, run)
    # letter-b's one run is smooth enough for 100 ms moves: nothing split.
    letter = load_plan(LETTER_B)
    with monkeypatch.context() as m:
        m.setattr(moves, "SPEED_MARGIN_DB", -math.inf)
        unsplit = prepare(letter, overrides=LONG).job
    assert [e.line for e in prepare(letter, overrides=LONG).job.entries] == [
        e.line for e in unsplit.entries
    ]


def _exact_speed_snr(tag, job, setpoints, run: int) -> tuple[float, float]:
    """The stated figures, computed again from the moves as sent: the board's accumulators
    replayed with the firmware's arithmetic from the job's first command, each draw move's
    exact motion (the rates summed), against the plan; and the whole steps' expected noise."""
    accumulators = (0, 0)
    start = {}
    for i, entry in enumerate(job.entries):
        if entry.move is not None:
            start[i] = accumulators
            _, accumulators = execute(entry.move, accumulators)
    ids = [i for i, e in enumerate(job.entries) if e.kind == "draw" and e.run == run]
    here = np.array(job.entries[ids[0] - 1].steps, dtype=float)
    path = [here + np.array(start[ids[0]]) / ACCUMULATOR_STEP]
    for i in ids:
        move = job.entries[i].move
        base = np.array(job.entries[i - 1].steps, dtype=float)
        ticks = np.arange(1, move.ticks + 1)
        sums = []
        for axis in (0, 1):
            loaded = AxisStart.load(move.rate[axis], move.accel[axis], move.jerk[axis])
            rates = [loaded.rate_at(int(k)) for k in ticks]
            sums.append(np.cumsum(np.array(rates, dtype=float)) + start[i][axis])
        path.extend(base + np.column_stack(sums) / ACCUMULATOR_STEP)
    exact = np.array(path) - 0.5
    reference = run_reference(tag, job.runs[run], setpoints.matrix, setpoints.offset)
    plan = reference(np.arange(len(exact)) / TICK_HZ) @ MOTOR_AXES.T * job.steps_per_mm
    w = round(0.01 * TICK_HZ)
    speed = (plan[2 * w :] - plan[: -2 * w]) / 0.02
    error = ((exact - plan)[2 * w :] - (exact - plan)[: -2 * w]) / 0.02
    signal = (speed**2).sum()
    steps = len(speed) * 2 * (2 / 12) / 0.02**2
    return 10 * math.log10(signal / (error**2).sum()), 10 * math.log10(signal / steps)


@pytest.mark.parametrize(
    ("plan", "overrides"), [(CAE, LONG), (LETTER_B, ("motion.jerk=false",))], ids=["T3", "LT"]
)
def test_the_stated_speed_figures_are_the_moves_exact_motions(plan, overrides):
    """With ``T3`` and with ``LT`` moves (no jerk: the board's rate changes by the same
    acceleration every tick)."""
    tag = load_plan(plan)
    prepared = prepare(tag, overrides=overrides)
    job = prepared.job
    for run in range(len(job.runs)):
        moves_db, steps_db = _exact_speed_snr(tag, job, prepared.setpoints, run)
        assert job.run_speed_snr[run] == pytest.approx(moves_db, abs=0.01)
        assert job.run_step_snr[run] == pytest.approx(steps_db, abs=0.01)


def test_each_speed_error_counts_for_the_move_holding_its_instant():
    """A run's speed error, taken over ±10 ms at each tick, counts for the move that tick is
    in (the move split for it): two ticks in a row off the plan err in the speeds 10 ms either
    side of them, at the first move's last tick, the second's first and two of the third's."""
    half = round(moves.SPEED_WINDOW * TICK_HZ)  # 250 ticks
    span = 2 * half / TICK_HZ
    planned = np.column_stack([np.arange(6 * half + 1) * 0.01, np.zeros(6 * half + 1)])
    motion = planned.copy()
    motion[3 * half, 0] += 1.0  # tick 750: a step off on motor 1
    motion[3 * half + 1, 1] += 2.0  # tick 751: two steps off on motor 2
    # Moves of ticks 1-500, 501-850 and 851-1500; speeds at ticks 500 and 501 (the first
    # move's last tick, the second's first), 1000 and 1001 (the third move's) take the errors.
    bounds = np.array([0, 2 * half, 3 * half + 100])
    per_move, signal, steps_noise = moves._speed_figures(motion, planned, bounds)
    assert per_move.tolist() == pytest.approx([1 / span**2, 4 / span**2, 5 / span**2])
    speeds = len(planned) - 2 * half  # ticks 250-1250
    assert signal == pytest.approx(speeds * (0.01 * TICK_HZ) ** 2)
    assert steps_noise == pytest.approx(speeds * 2 * (2 / 12) / span**2)


def test_the_fifo_holds_the_promised_drawing_ahead_and_the_board_never_runs_dry(tmp_path):
    """100 ms setpoints promise serial.fifo x 0.1 s ahead; the split moves need a deeper FIFO
    for it. On the simulated board every move of a run starts on the tick the one before
    ends."""
    tag = load_plan(CAE)
    prepared = prepare(tag, overrides=LONG)
    job, fifo = prepared.job, prepared.profile["serial.fifo"]
    assert fifo < job.fifo <= 32
    durations = np.array([e.duration for e in job.entries])
    held = np.convolve(durations, np.ones(job.fifo + 1), mode="valid")
    assert held.min() >= fifo * 0.1 - 1e-9
    shallower = np.convolve(durations, np.ones(job.fifo), mode="valid")
    assert shallower.min() < fifo * 0.1  # and no deeper than it needs
    device = SimulatedEBB()
    url = attach_device(device, f"a3length{os.getpid()}_{next(_names)}")
    report = draw(tag, tmp_path / "r", prepared=replace(prepared, port=url), pictures=False).report
    assert report["completed"] and report["stalls"] == 0
    assert report["details"]["fifo"] == job.fifo
    assert report["details"]["most_on_board"] == job.fifo + 1
    segments = [s for s in device.recorder.segments if s.line.startswith(b"T3")]
    gaps = [b.load_tick - (a.load_tick + a.ticks) for a, b in pairwise(segments)]
    within_runs = [g for g in gaps if g < 25 * 50]  # a pen move and travel between runs
    assert within_runs and max(within_runs) == 0
