"""A USB stall mid-run is one host stall of about its length, wherever it falls."""

from __future__ import annotations

import pytest

from sim.ebb.device import SimulatedEBB
from tagbot.axidraw.machine import prepare
from tagbot.draw import draw
from tagbot.io.planfile import load_plan

from .conftest import LETTER_B


@pytest.fixture(scope="module")
def job():
    return prepare(load_plan(LETTER_B))


@pytest.mark.parametrize("where", [0.2, 0.45, 0.5, 0.54, 0.8])
def test_a_stall_while_the_host_sends_or_polls_is_counted_once(job, tmp_path, monkeypatch, where):
    """1.5 s without USB at ``where`` of letter-b's run: the host is held in a motion line's
    send or in a poll; either way the board runs dry once, for the stall less what it held."""
    import sim.ebb.transport as transport

    attach = transport.attach_device
    at = job.job.run_start[0] + where * job.setpoints.runs[0].duration

    def stalled(device: SimulatedEBB, name: str) -> str:
        device.stall_usb(at, 1.5)
        return attach(device, name)

    monkeypatch.setattr(transport, "attach_device", stalled)
    report = draw(job.tag, tmp_path, prepared=job, pictures=False).report
    assert report["completed"] and report["stalls"] == 1
    held = (report["details"]["fifo"] + 1) * job.profile["motion.dt"]
    assert 1.5 - held - 0.05 <= report["stalled_s"] <= 1.5
