"""What an arm run logs and reports at its edges (issue 34): warnings logged as they are
returned, the USB adapter's latency timer behind a spy:// URL or found under /sys, the
simulator's own geometry in the executed trace, a host stall up to its last instant."""

from __future__ import annotations

import logging
import math
import pathlib

import numpy as np
import pytest

from sim.dynamixel import ArmGeometry
from tagbot.arm import load_profile, prepare
from tagbot.arm.kinematics import Arm
from tagbot.arm.run import (
    Budget,
    _outside_limits,
    _stall_warnings,
    draw_arm,
    simulated_chain,
)
from tagbot.draw import run_report
from tagbot.errors import ConnectionLost, DeviceError

from .conftest import hook_from_its_end, small_tag


def test_draw_arm_reads_the_latency_timer_under_sys(tmp_path, monkeypatch, caplog) -> None:
    """draw_arm (no sysfs of its own) looks for the adapter's latency timer where Linux mounts
    sysfs, /sys, and logs the warning before it opens the port (here: no such device, so opening
    it fails)."""
    timer = "/sys/bus/usb-serial/devices/ttyUSB9/latency_timer"
    read_text = pathlib.Path.read_text

    def fake(self, *args, **kwargs):
        return "16\n" if str(self) == timer else read_text(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "read_text", fake)
    port = str(tmp_path / "ttyUSB9")
    with caplog.at_level(logging.WARNING, logger="tagbot.arm.run"), pytest.raises(DeviceError):
        draw_arm(small_tag(), load_profile(), port=port)
    assert any(
        m.startswith(f"{port} is a USB serial adapter (ttyUSB9) with a 16 ms latency timer")
        and f"echo 1 | sudo tee {timer}" in m
        for m in caplog.messages
    )


def test_a_start_outside_the_limits_is_logged_as_reported(tmp_path, record, caplog) -> None:
    """The warning for a joint starting outside its limits is logged, word for word as the run
    reports it."""
    sim = record(simulated_chain(load_profile(), at_park=False))  # elbow straight: 0°
    job = prepare(small_tag(), port=sim.url)

    def progress(done: int, total: int) -> None:  # the warning comes before the first tick
        raise ConnectionLost("enough")

    with caplog.at_level(logging.WARNING, logger="tagbot.arm.run"):
        warnings = job.run(tmp_path, progress=progress).warnings
    message = "elbow starts at 0.0° outside elbow.min_deg..max_deg (10..160°): moving it back"
    assert message in warnings and message in caplog.messages


def _slow_run() -> dict:
    """A report's run of plan 0 drawn on its path but 5 dB below the 25 dB speed SNR budget."""
    return {
        "plan": 0,
        "executed_start": 1.0,
        "planned_duration": 2.0,
        "path_deviation_max_mm": 0.0,
        "speed_snr_db": 20.0,
    }


def test_the_budgets_warning_is_logged_as_returned(caplog) -> None:
    """A run below the speed SNR: the budget's warning is logged, word for word as returned."""
    job = prepare(small_tag())
    budget = Budget(job.program, job.profile, [(1.5, 0.2)], np.zeros((0, 2)))
    with caplog.at_level(logging.WARNING, logger="tagbot.arm.run"):
        out = budget({"runs": [_slow_run()]})
    assert out == [
        "run 1 (plan 0): speed SNR 20.0 dB below 25 dB: 1 host stall (200 ms) with the pen down"
    ]
    assert caplog.messages == out


def test_a_stall_with_the_pen_down_at_its_last_instant_is_warned() -> None:
    """A host stall from 0.25 s for 0.5 s: a pen-down sample at 0.75 s (its last instant) is
    still in it; one just after, or pen-up samples inside it, are not."""
    job = prepare(small_tag())

    def warned(samples: list[list[float]]) -> list[str]:
        return _stall_warnings([(0.25, 0.5)], np.array(samples), job.program)

    up_inside = [[0.0, 0.0, 0.0, 1.0], [0.5, 0.0, 0.0, 0.0]]
    assert warned([*up_inside, [0.75, 0.0, 0.0, 1.0]]) == [
        "the host stalled 500 ms at 0.250 s (executed clock) with the pen down: no goal left for"
        " that long and the pen stood on the paper; a busy host (see details.realtime)"
    ]
    assert warned([*up_inside, [math.nextafter(0.75, 1.0), 0.0, 0.0, 1.0]]) == []


def test_the_trace_follows_the_simulated_arms_own_geometry(tmp_path, record) -> None:
    """A simulated arm built with a forearm 20 mm longer than the profile says (its recorder set
    to it): the executed trace is where that arm's pen went, not where the profile's arm would
    have put it. Its pen-down samples lie on the longer arm's forward kinematics of the joints
    as they ran, far (mm) from the profile's."""
    profile = load_profile()
    real = load_profile(None, [f"arm.l2={profile['arm.l2'] + 20.0!r}"])
    chain = simulated_chain(real)
    assert isinstance(chain.geometry, ArmGeometry) and chain.geometry.l2_mm == real["arm.l2"]
    sim = record(chain)
    job = prepare(small_tag(), port=sim.url)
    run = job.run(tmp_path)
    assert run.error is None and chain.geometry.l2_mm == real["arm.l2"]
    report = run_report(run)
    # The planned path (the profile's arm) against the trace: the longer forearm puts the pen
    # millimetres away from it.
    assert report["runs"][0]["path_deviation_max_mm"] > 2.0
    q = job.program.angles
    planned_real = Arm.from_profile(real).fk(q).reshape(-1, 2)
    planned_profile = Arm.from_profile(profile).fk(q).reshape(-1, 2)
    assert np.max(np.hypot(*(planned_real - planned_profile).T)) > 5.0


def test_a_clean_runs_details_name_its_resyncs_and_their_delay(tmp_path) -> None:
    """A clean simulated run resynchronised nothing: resyncs 0 and resync_delay_s 0.0."""
    run = prepare(small_tag()).run(tmp_path)
    details = run_report(run)["details"]
    assert details["resyncs"] == 0 and details["resync_delay_s"] == 0.0


def test_a_joint_starting_exactly_at_its_lower_limit_is_not_warned() -> None:
    """Limits on whole ticks (shoulder.min_deg -90° = tick 0, elbow.min_deg 0° = tick 2048): joints
    read back exactly there start inside them, no warning; the elbow one tick lower is warned."""
    profile = load_profile(None, ["shoulder.min_deg=-90", "elbow.min_deg=0"])
    pen = profile["pen.up"]
    assert _outside_limits(np.array([0, 2048, pen]), profile) == []
    assert _outside_limits(np.array([0, 2047, pen]), profile) == [
        "elbow starts at -0.1° outside elbow.min_deg..max_deg (0..160°): moving it back"
    ]


def test_a_slow_runs_cause_is_the_follow_where_its_rounded_plan_keeps_3_db_over_budget() -> None:
    """A run below the speed SNR whose plan, its goals rounded to whole ticks, still has 28.2 dB
    (3 dB or more over the 25 dB budget): the rounding does not explain it, the servos' follow
    does."""
    job = prepare(hook_from_its_end(), overrides=("place.scale=12",))
    budget = Budget(job.program, job.profile, [], np.zeros((0, 2)))
    snr = budget.rounded(0)[1]
    assert 28.0 <= snr < 29.0
    assert budget({"runs": [_slow_run()]}) == [
        "run 1 (plan 0): speed SNR 20.0 dB below 25 dB: the servos' follow beyond the retiming's"
        " model (motion.max_deviation)"
    ]
