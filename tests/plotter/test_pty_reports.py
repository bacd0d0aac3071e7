"""Over a real serial port (a pseudo-terminal): the report says only what 5 Hz status reports
support, and pen moves never count as drawing."""

from __future__ import annotations

import math

from sim.grbl import SimulatedGrbl
from sim.grbl.transport import serve_pty
from tagbot.cli import _draw_summary
from tagbot.clock import MonotonicClock, RealTime
from tagbot.draw import draw
from tagbot.metrics import SPARSE_SNR_NOTE, compare_execution
from tagbot.model import Plan, Tag
from tagbot.plotter import load_profile
from tagbot.plotter.machine import prepare, simulated_pen
from tagbot.plotter.profile import device_settings

ZPEN = (
    "limits.x_acceleration=5000",
    "limits.y_acceleration=5000",
    "place.scale=20",
    "place.align=bottom-left",
    "motion.park=false",
    "pen.dwell=0.05",
    "pen.feed=3000",
    "limits.z_max_feed=3000",
    "limits.z_acceleration=1000",
)


def _tag() -> Tag:
    plan = Plan(
        targets=[[0.0, 0.0], [2.0, 1.0], [3.0, -1.0]],
        dt=[0.0, 0.25],
        mu=[math.log(0.3)] * 2,
        sigma=[0.3] * 2,
        phi1=[0.3, -0.2],
        phi2=[0.0, 0.0],
    )
    return Tag(plans=(plan,))


def test_zpen_over_a_pty_reports_no_speed_snr_and_the_recorders_drawing_time(tmp_path):
    profile = load_profile("zpen", ZPEN)
    device = SimulatedGrbl(device_settings(profile), clock="real", **simulated_pen(profile))
    path, stop = serve_pty(device)
    try:
        result = draw(_tag(), tmp_path, port=path, profile="zpen", overrides=ZPEN, pictures=False)
    finally:
        stop()
    report = result.report
    assert report["executed_source"].startswith("status reports, 5 Hz")
    # Only what was measured: no speed SNR from 5 Hz reports, and the report says why.
    assert report["speed_snr_db"] is None and report["speed_snr_note"] == SPARSE_SNR_NOTE
    assert [run["speed_snr_db"] for run in report["runs"]] == [None]
    assert "speed SNR not measured (status reports)" in _draw_summary(report, "out")
    assert report["path_deviation_max_mm"] < 0.05
    # The Z moves (1 per pen change) are not drawing: the ratio the reports give is the one the
    # device's own 1 ms recorder gives for the same run, within 1 %.
    job = prepare(_tag(), profile="zpen", overrides=ZPEN)
    trace = device.trace(0.001)[:, [0, 1, 2, 4]]
    recorder = compare_execution(job.program.planned_runs, trace, plans=job.program.run_plans)
    assert abs(report["drawing_duration_ratio"] / recorder.duration_ratio - 1) < 0.01
    assert abs(recorder.duration_ratio - 1) < 0.01
    # A Z pen with a dwell still stops before each run: what its start holds is named, and the
    # stream ran real-time exactly where the system permits it.
    start = job.program.min_buffered_start
    assert 0 < start < math.inf and report["details"]["min_buffered_start_s"] == start
    probe = RealTime(MonotonicClock())
    probe.end()
    assert report["details"]["realtime"] is probe.fifo
