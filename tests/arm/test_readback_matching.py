"""Which request a read-back reply answers, when the adapter holds replies back for a while.

Status packets carry no sequence number: the driver matches replies to requests by their order.
A burst of replies held back by the adapter must still be stamped with their own requests'
instants, never with later ones; a hold longer than ``bus.silence_timeout`` (0.25 s here),
counted from the first request a servo has not answered, is a fault. Simulated time.
"""

from __future__ import annotations

import pytest

from tagbot.arm import load_profile, prepare
from tagbot.arm.run import simulated_chain
from tagbot.errors import DeviceTimeout

from .conftest import two_plan_tag


def _held_once(record, tmp_path, hold: float):
    """The two-plan tag, replies 50 ms late, one of them held ``hold`` s after tick 300 (those
    behind it wait: the adapter keeps them in order)."""
    profile = load_profile()
    sim = record(simulated_chain(profile))
    sim.chain.set_reply_faults(latency=0.05)
    phase: list[int] = []

    def progress(done: int, total: int) -> None:
        if done > 300 and not phase:
            phase.append(done)
            sim.chain.set_reply_faults(latency=hold)
        elif len(phase) == 1 and done > phase[0]:
            phase.append(done)
            sim.chain.set_reply_faults(latency=0.05)

    job = prepare(two_plan_tag(), port=sim.url)
    return job, job.run(tmp_path, progress=progress), phase[0]


@pytest.mark.parametrize("hold", [0.05, 0.2, 0.25])
def test_replies_held_back_are_kept_with_their_own_requests(record, tmp_path, hold) -> None:
    job, run, _ = _held_once(record, tmp_path, hold)
    assert run.error is None, run.error
    d = run.details
    assert d["readback_requests"] == len(job.program)
    assert d["readback_replies"] == 3 * d["readbacks"] >= 3 * (len(job.program) - 5)
    assert d["readback_missed_replies"] == d["readback_stale_replies"] == 0
    # No reply is taken sooner than the adapter's 50 ms after the request it answers.
    assert d["reply_delay_p50_ms"] >= 50
    assert 1e3 * hold < d["reply_delay_max_ms"] < 1e3 * hold + 5
    # Each read-back is where the arm stood at its own instant.
    assert d["joint_tracking_error"]["max"] < 0.5


def test_a_hold_past_the_silence_timeout_is_a_fault_not_a_shifted_trace(record, tmp_path):
    _, run, held = _held_once(record, tmp_path, 0.3)
    error = run.error
    assert isinstance(error, DeviceTimeout)
    assert "did not answer SYNC_READ of present positions for 0.25 s" in str(error)
    tick = int(error.where.split()[1])
    # 0.25 s (25 ticks) after the request whose reply was held: not later.
    assert held + 24 <= tick <= held + 26
    d = run.details
    assert d["reply_delay_p50_ms"] >= 50 and d["reply_delay_max_ms"] < 60
    assert d["readback_missed_replies"] == d["readback_stale_replies"] == 0
    assert d["joint_tracking_error"]["max"] < 0.5
