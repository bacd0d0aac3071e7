"""Short runs that change fast: the default move length keeps more of their planned speed."""

from __future__ import annotations

import math

import numpy as np

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


def test_a_short_fast_run_keeps_its_speed_with_the_default_moves():
    default, long_moves = _speed_snr(()), _speed_snr(("motion.dt=0.05",))
    assert default >= 37.0
    assert default >= long_moves + 0.5
