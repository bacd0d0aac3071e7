"""Short runs that change fast: their moves are as short as they need, whatever the setpoints'
step (the default's 25 ms or longer)."""

from __future__ import annotations

import math

import numpy as np

import tagbot.axidraw.moves as moves
from tagbot.axidraw.machine import prepare, timeline
from tagbot.metrics import compare_execution
from tagbot.model import Plan, Tag


def _hook() -> Tag:
    """A 0.4 s hook of two lognormal strokes (about 8 mm, peak near 80 mm/s)."""
    stroke = dict(
        dt=[0.0, 0.08],
        mu=[math.log(0.12), math.log(0.1)],
        sigma=[0.3, 0.3],
        phi1=[0.0, 0.0],
        phi2=[1.0, -2.0],
    )
    return Tag(plans=(Plan(targets=[[0.0, 0.0], [8.0, 2.0], [5.0, 6.0]], start=0.0, **stroke),))


def _speed_snr(overrides: tuple[str, ...]) -> float:
    """The run's speed SNR, dB, of the job's own tick record (what the board steps) against
    the plan, at its natural size."""
    job = prepare(_hook(), overrides=("place.scale=1", *overrides))
    table = timeline(job.job, 0.001)
    executed = np.column_stack([table.t, table.xy, table.pen])
    (run,) = compare_execution(job._planned_runs(), executed).runs
    assert run.snr_db is not None
    return run.snr_db


def test_a_short_fast_run_keeps_its_speed_with_long_setpoints(monkeypatch):
    """50 ms setpoints: the run's moves are shortened where its speed changes fast, and it
    keeps the default's speed; 50 ms moves throughout (no move shortened) lose 0.5 dB."""
    default, long_setpoints = _speed_snr(()), _speed_snr(("motion.dt=0.05",))
    assert default >= 37.0
    assert long_setpoints >= default - 0.1
    monkeypatch.setattr(moves, "SPEED_MARGIN_DB", -math.inf)  # no move shortened
    assert default >= _speed_snr(("motion.dt=0.05",)) + 0.5
