"""The unmodified dynamixel-sdk over a real pseudo-terminal served by the simulator (real time)."""

from __future__ import annotations

import os
import time

import dynamixel_sdk as sdk
import pytest
from click.testing import CliRunner

from sim.dynamixel import serve_pty
from tagbot.arm import build_program, draw_arm, load_profile
from tagbot.arm import cli as arm_cli
from tagbot.arm.run import simulated_chain
from tagbot.errors import DeviceTimeout

from .conftest import FAST, GOAL_POSITION, Recorded, small_tag


def _open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


@pytest.fixture
def served(record):
    """A real-time chain for the FAST profile at park, served on a pty: ``(profile, sim, path)``."""
    profile = load_profile(None, FAST)
    sim: Recorded = record(simulated_chain(profile, real_time=True))
    path, stop = serve_pty(sim.chain)
    yield profile, sim, path
    stop()


def test_streams_over_a_pseudo_terminal(served) -> None:
    profile, sim, path = served
    fds = _open_fds()
    run = draw_arm(small_tag(), profile, path)
    assert _open_fds() == fds  # the port is closed
    n = len(run.joints)
    assert run.stats["ticks_sent"] == n and run.stats["simulated"] is False
    assert run.stats["port"] == path
    for column, id in enumerate((1, 2, 3)):
        assert sim.values(id, GOAL_POSITION)[1:] == run.program.goals[:, column].tolist()
    # Executed trace: present positions read back at 100 Hz through FK (those inside a resync's
    # gap, if the host stalled, are left out of the program's timeline).
    ex = run.executed
    assert ex.shape[1] == 4 and 0.9 * n < len(ex) <= run.stats["readbacks"]
    assert ex[:, 3].max() == 1.0
    tracking = run.stats["joint_tracking_error"]
    assert tracking["mean"] < 1.0  # degrees; real time on a shared machine: generous
    assert run.stats["max_lateness_ms"] >= 0.0 and 0 <= run.stats["late_ticks"] <= n
    assert sim.servo(3).get("goal_position") == profile["pen.up"]


def test_a_silent_servo_over_the_pty_is_a_timeout_and_a_safe_stop(served) -> None:
    profile, sim, path = served
    program = build_program(small_tag(), profile)

    def progress(done: int, total: int) -> None:
        if done > 20:
            sim.chain.silence(1)

    with pytest.raises(DeviceTimeout) as raised:
        draw_arm(small_tag(), profile, path, progress)
    tick = int(raised.value.where.split()[1])
    # Silenced after tick 21 was sent: more than bus.max_missed = 5 read-backs (one a tick)
    # missed, tick 21's own among them when the silence comes before its reply (a race with
    # the progress callback: tick 26), or, if the host is so loaded that the others' replies
    # are late too, 0.25 s without a reply.
    assert 26 <= tick <= 21 + 28 and "servo 1 (shoulder) did not answer" in str(raised.value)
    # The last packets are on their way through the pty: give the server a moment.
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline and (sim.servo(1).torque or sim.servo(2).torque):
        time.sleep(0.01)
    with sim.chain.lock:
        assert sim.servo(3).get("goal_position") == profile["pen.up"]
        assert not sim.servo(1).torque and not sim.servo(2).torque
        shoulder = sim.values(1, GOAL_POSITION)[1:]
    assert shoulder == program.goals[:tick, 0].tolist()


def test_the_unmodified_port_handler_opens_the_cli_pty(monkeypatch) -> None:
    """``tagbot sim arm`` serves a chain the SDK's own PortHandler (serial.Serial) can ping."""
    import sim.dynamixel

    served: dict[str, object] = {}
    real_serve = sim.dynamixel.serve_pty

    def serve(chain):  # remember the path the command is about to print
        path, stop = real_serve(chain)
        served["path"] = path
        return path, stop

    def ping_then_interrupt() -> None:
        port = sdk.PortHandler(served["path"])
        try:
            assert port.openPort()
            ph = sdk.PacketHandler(2.0)
            for id in (1, 2, 3, 4):
                # The SDK waits about 34 ms for a reply; on a host busy with other work the
                # pty's thread may answer later: ask again (the absent servo never answers).
                for _ in range(3):
                    model, result, _ = ph.ping(port, id)
                    if result != sdk.COMM_RX_TIMEOUT:
                        break
                served[str(id)] = (model, result)
        finally:
            port.closePort()
        raise KeyboardInterrupt

    monkeypatch.setattr(sim.dynamixel, "serve_pty", serve)
    monkeypatch.setattr(arm_cli, "_wait_for_interrupt", ping_then_interrupt)
    result = CliRunner().invoke(arm_cli.sim_arm_command, ["--set", "pen.id=4"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0] == served["path"]
    assert served["1"] == (1020, sdk.COMM_SUCCESS) and served["2"] == (1020, sdk.COMM_SUCCESS)
    assert served["4"] == (1060, sdk.COMM_SUCCESS) and served["3"][1] == sdk.COMM_RX_TIMEOUT
    assert "stopped" in result.stderr


def test_the_cli_pty_can_delay_and_lose_replies(monkeypatch) -> None:
    import sim.dynamixel

    served: dict[str, object] = {}
    real_serve = sim.dynamixel.serve_pty

    def serve(chain):
        served["chain"] = chain
        return real_serve(chain)

    def interrupt() -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(sim.dynamixel, "serve_pty", serve)
    monkeypatch.setattr(arm_cli, "_wait_for_interrupt", interrupt)
    args = ["--reply-latency", "0.05", "--reply-jitter", "0.01", "--drop", "0.02", "--seed", "4"]
    result = CliRunner().invoke(arm_cli.sim_arm_command, args)
    assert result.exit_code == 0, result.output
    chain = served["chain"]
    assert (chain.reply_latency, chain.reply_jitter, chain.reply_drop) == (0.05, 0.01, 0.02)
    assert "(replies 50+10 ms late, 2 % lost)" in result.stderr
    bad = CliRunner().invoke(arm_cli.sim_arm_command, ["--drop", "2"])
    assert bad.exit_code == 2 and "--drop" in bad.output
