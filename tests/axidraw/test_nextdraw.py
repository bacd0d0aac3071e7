"""The NextDraw profiles: the makers' figures, the brushless pen lift on RB2 through the
simulated board, the firmware they need, and ``--port auto`` finding their boards."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from itertools import count

import numpy as np
import pytest

from sim.ebb.device import SimulatedEBB
from sim.ebb.transport import attach_device
from tagbot.axidraw.machine import find_port, prepare
from tagbot.axidraw.profile import load_profile, packaged_profiles
from tagbot.draw import draw
from tagbot.errors import DeviceError, PortError, ProfileError
from tagbot.io.planfile import load_plan

from .conftest import LETTER_B

INCH = 25.4
_names = count()

# Written from the makers' NextDraw software 1.5.0 (models.py, pen_handling.py, nextdraw_conf.py)
# and plotink 1.14.3 (ebb3_serial.py), independently of the TOML files.
NEXTDRAW = {
    "nextdraw8511": ("NextDraw 8511", 11.81, 8.58),
    "nextdraw1117": ("NextDraw 1117", 16.93, 11.69),
    "nextdraw2234": ("NextDraw 2234", 34.02, 23.39),
}
BRUSHLESS = {  # models.py z_motors[1], the narrow-band brushless pen-lift motor
    "pen.pin": 2,
    "pen.servo_min": 5400,
    "pen.servo_max": 12600,
    "pen.sweep_time": 0.070,
    "pen.move_min": 0.020,
    "pen.move_slope": 0.00128,
    "pen.period": 0.003,  # SC,8,1: one 3 ms channel
    "pen.up": 60.0,
    "pen.down": 40.0,  # nextdraw_conf.py pen_pos_down
    "pen.rate_raise": 75.0,
    "pen.rate_lower": 50.0,
}
SAME_AS_AXIDRAW = {  # 2032 steps/inch at 16x, 8.6979 in/s at 16x, 75 % of it pen up
    "motors.steps_per_mm_16x": 2032 / INCH,
    "limits.draw_speed": 8.6979 * INCH,
    "limits.travel_speed": 0.75 * 8.6979 * INCH,
}


def _url(device: SimulatedEBB) -> str:
    return attach_device(device, f"ndtest{os.getpid()}_{next(_names)}")


def test_every_shipped_profile_loads():
    names = packaged_profiles()
    assert {"default", "v3a3", "sea3", "minikit", *NEXTDRAW} <= set(names)
    for name in names:
        assert load_profile(name)["machine.model"]


@pytest.mark.parametrize("name", sorted(NEXTDRAW))
def test_nextdraw_figures_are_the_makers(name):
    model, x_in, y_in = NEXTDRAW[name]
    p = load_profile(name)
    assert p["machine.model"] == model
    x_min, x_max, y_min, y_max = p.bed
    assert (x_min, y_min) == (0.0, 0.0)
    assert x_max == pytest.approx(x_in * INCH, abs=0.05)
    assert y_max == pytest.approx(y_in * INCH, abs=0.1)
    for key, value in {**BRUSHLESS, **SAME_AS_AXIDRAW}.items():
        assert p[key] == pytest.approx(value, abs=0.5 if key.startswith("limits") else 1e-9), key
    assert p.min_firmware == (3, 0, 2)  # plotink ebb3_serial: MIN_VERSION_STRING = "3.0.2"
    assert p.servo_channels == 1


def test_brushless_pen_positions_rates_and_times():
    p = load_profile("nextdraw8511")
    assert p.servo_position(60) == 5400 + 72 * 60 and p.servo_position(40) == 5400 + 72 * 40
    # SC,11/12: range x 0.03 ms / 70 ms x rate, as the NextDraw software sends them.
    assert p.servo_rate(75) == round(7200 * 0.03 / 70 * 75) == 231
    assert p.servo_rate(50) == 154
    # ((1.28 x 20 + 20)^4 + (70 x 20 / rate)^4)^(1/4) ms, whole ms.
    assert p.pen_time(down=True) == 0.047
    assert p.pen_time(down=False) == 0.045


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["pen.period=0.005"], "pen.period: must be 1 to 8 servo slots of 0.003 s"),
        (["pen.period=0.027"], "pen.period: must be 1 to 8 servo slots"),
        (['machine.min_firmware="2.8.1"'], "machine.min_firmware: must be a version"),
        (['machine.min_firmware="3.1"'], "machine.min_firmware: must be a version"),
    ],
)
def test_bad_pen_period_and_firmware_are_refused(overrides, message):
    with pytest.raises(ProfileError, match=message):
        load_profile("nextdraw8511", overrides)


@pytest.mark.parametrize("name", sorted(NEXTDRAW))
def test_a_tag_drawn_on_each_nextdraw(name, tmp_path):
    tag = load_plan(LETTER_B)
    job = prepare(tag, profile=name)
    device = SimulatedEBB(pen_pin=2)
    report = draw(tag, tmp_path, prepared=replace(job, port=_url(device)), pictures=False).report
    assert report["completed"]
    assert report["path_deviation_max_mm"] <= 0.02
    sent = (tmp_path / "moves.txt").read_text().splitlines()
    assert {line for line in sent if line.startswith("SP")} == {"SP,0,47,2", "SP,1,45,2"}
    # The pen pulses repeat every 3 ms (SC,8,1) between its heights on RB2.
    moving = [s for s in device.recorder.servo if s.target]
    assert moving and {s.period for s in moving} == {0.003}
    assert {s.target for s in moving} == {5400 + 72 * 60, 5400 + 72 * 40}
    p = load_profile(name)
    width = device.recorder.trace().pen
    assert set(width[width > 0]) >= {p.servo_position(60), p.servo_position(40)}


def test_without_a_port_the_simulated_board_is_wired_as_the_profile(tmp_path):
    """The in-process board's pen is on the profile's pin: the pen is down as long as the
    plan has it down (on a board wired to RB1 it would never get a pulse)."""
    tag = load_plan(LETTER_B)
    draw(tag, tmp_path, device="axidraw", profile="nextdraw8511", pictures=False)
    executed = np.loadtxt(tmp_path / "executed.csv", delimiter=",", skiprows=1)
    planned = np.loadtxt(tmp_path / "motion.csv", delimiter=",", skiprows=1)
    down = executed[:, 3].sum() * np.median(np.diff(executed[:, 0]))
    assert executed[0, 3] == 0 and executed[-1, 3] == 0
    assert down == pytest.approx(planned[:, 6].sum() * np.median(np.diff(planned[:, 0])), rel=0.01)


def test_the_pen_moves_only_on_the_pin_it_is_wired_to():
    """SP's pin routes the pen pulses (RB1 when none is given): a NextDraw's SP,..,2 on a
    board whose pen is on RB1 leaves that pen without a pulse, and a plain SP takes them back."""
    axidraw, nextdraw = SimulatedEBB(pen_pin=1), SimulatedEBB(pen_pin=2)
    for device in (axidraw, nextdraw):
        device.write(b"SC,4,9720\rSC,5,8280\rSP,0,10,2\r")
        device.run_until_idle()
    assert nextdraw.pen_position() == 8280
    assert axidraw.pen_position() == 0  # RB1's output stopped when SP moved to RB2
    assert not nextdraw.pen_up and not axidraw.pen_up  # the firmware's pen state: down
    nextdraw.write(b"SP,1,10\r")
    nextdraw.run_until_idle()
    assert nextdraw.pen_position() == 0 and nextdraw.pen_up


def test_a_nextdraw_refuses_firmware_older_than_its_software_does(tmp_path):
    tag = load_plan(LETTER_B)
    job = prepare(tag, profile="nextdraw8511")
    device = SimulatedEBB(version="3.0.1", pen_pin=2)
    with pytest.raises(DeviceError, match=r"firmware 3\.0\.1 is not supported.*3\.0\.2.*NextDraw"):
        draw(tag, tmp_path, prepared=replace(job, port=_url(device)), pictures=False)
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["executed"] == 0 and not device.recorder.moves()


class _Port(tuple):
    """What pyserial's comports() yields, read by index: device, description, hwid."""


@pytest.mark.parametrize(
    ("ports", "found"),
    [
        # A NextDraw's EBB seen by VID:PID alone (a generic description, as on Windows).
        (
            [("COM3", "USB Serial Device (COM3)", "USB VID:PID=04D8:FD92 SER=12 LOCATION=1-1")],
            "COM3",
        ),
        # By its name first, whatever comes before it.
        (
            [
                ("/dev/ttyACM0", "Arduino Uno", "USB VID:PID=2341:0043"),
                ("/dev/ttyACM1", "EiBotBoard", "USB VID:PID=04D8:FD92"),
            ],
            "/dev/ttyACM1",
        ),
        ([("/dev/ttyACM0", "Arduino Uno", "USB VID:PID=2341:0043")], None),
    ],
)
def test_port_auto_finds_any_ebb_by_its_usb_identity(monkeypatch, ports, found):
    from plotink import ebb_serial

    monkeypatch.setattr(ebb_serial, "comports", lambda: [_Port(p) for p in ports])
    if found is None:
        with pytest.raises(PortError, match="no EiBotBoard found"):
            find_port()
    else:
        assert find_port() == found


def test_sim_axidraw_serves_a_board_with_its_pen_on_the_pin_asked(monkeypatch):
    from click.testing import CliRunner

    from sim.ebb import transport
    from tagbot.axidraw import sim_cli

    served: list[SimulatedEBB] = []

    def serve(device: SimulatedEBB) -> tuple[str, object]:
        served.append(device)
        return "/dev/pts/nowhere", lambda: None

    def interrupt() -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(transport, "serve_pty", serve)
    monkeypatch.setattr(sim_cli, "_wait_for_interrupt", interrupt)
    for args, rpn in (([], 4), (["--pen-pin", "2"], 5)):
        result = CliRunner().invoke(sim_cli.sim_axidraw_command, args)
        assert result.exit_code == 0, result.output
        assert served.pop().pen_rpn == rpn
    assert CliRunner().invoke(sim_cli.sim_axidraw_command, ["--pen-pin", "8"]).exit_code == 2
