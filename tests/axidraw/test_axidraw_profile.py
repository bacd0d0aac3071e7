"""AxiDraw profiles: the makers' figures, the models, overrides and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.axidraw.profile import load_profile, packaged_profiles
from tagbot.errors import ProfileError
from tagbot.io.planfile import load_plan
from tagbot.plotter.place import place
from tests.axidraw.conftest import CAE


def test_packaged_models_have_their_travel():
    assert packaged_profiles() == [
        "default",
        "minikit",
        "nextdraw1117",
        "nextdraw2234",
        "nextdraw8511",
        "sea3",
        "v3a3",
    ]
    travel = {name: load_profile(name).bed for name in packaged_profiles()}
    assert travel["default"] == (0.0, 300.0, 0.0, 218.0)  # 11.81 in x 8.58 in
    assert travel["v3a3"] == travel["sea3"] == (0.0, 430.0, 0.0, 297.0)
    assert travel["minikit"] == (0.0, 160.0, 0.0, 101.6)


def test_steps_servo_and_pen_timing_as_the_axidraw_cli():
    p = load_profile()
    assert p.steps_per_mm == 80.0  # 2032 steps per inch at 16x
    assert p.step_mode == 1
    assert p.servo_position(p["pen.up"]) == 20641  # 9855 + 17976 x 60 %
    assert p.servo_position(p["pen.down"]) == 15248
    assert p.servo_rate(p["pen.rate_raise"]) == 1618
    assert p.servo_rate(p["pen.rate_lower"]) == 1079
    # ((2.69 x 30 + 45)^4 + (200 x 30 / rate)^4)^(1/4) ms, whole ms
    assert p.pen_time(down=True) == 0.146
    assert p.pen_time(down=False) == 0.130
    eighth = load_profile(overrides=["motors.microstepping=8"])
    assert (eighth.steps_per_mm, eighth.step_mode) == (40.0, 2)
    same = load_profile(overrides=["pen.down=60"])
    assert same.pen_time(down=True) == 0.0


def test_placement_limits_hold_along_the_motor_axes():
    view = load_profile().placement()
    np.testing.assert_array_equal(view.axes @ [1.0, 0.0], [1.0, 1.0])
    np.testing.assert_array_equal(view.axes @ [0.0, 1.0], [1.0, -1.0])
    assert view.max_speed == (221.0, 221.0)
    assert view["bed.y_down"] is True


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["motors.microstepping=3"], "--set: motors.microstepping: must be one of 16, 8, 4, 2, 1"),
        (["limits.draw_speed=400"], "--set: limits.draw_speed: must be <= 312.438 mm/s"),
        (["motors.max_step_rate=30000"], "--set: motors.max_step_rate: must be <= 25000"),
        (["pen.up=120"], "--set: pen.up: must be <= 100"),
        (["bed.x_max=-1"], "--set: bed.x_max: must be > bed.x_min"),
        (["pen.colour=1"], "--set: pen.colour: unknown"),
        (["pen.pin=8"], "--set: pen.pin: must be <= 7"),
        (["serial.fifo=65"], "--set: serial.fifo: must be <= 64"),
        (["pen.servo_max=70000"], "--set: pen.servo_max: must be <= 65535"),
        (["pen.servo_min=30000"], "--set: pen.servo_max: must be > pen.servo_min"),
        (["motion.dt=0.00001"], "--set: motion.dt: must be >= 0.00004 s"),
        (["motion.max_dt=0.01"], "--set: motion.max_dt: must be >= motion.dt"),
        (["motion.park_x=400"], "--set: motion.park_x: outside the bed"),
        (["pen.rate_raise=10000"], "--set: pen.rate_raise: gives an SC,11/12 rate outside"),
    ],
)
def test_bad_values_are_one_line_naming_source_and_key(overrides, message):
    with pytest.raises(ProfileError) as e:
        load_profile(overrides=overrides)
    assert str(e.value).startswith(message)
    assert "\n" not in str(e.value)


def test_a_user_file_is_named_in_its_errors(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text("[bed]\nx_max = 500.0\n[motors]\nmicrostepping = 1\n", encoding="utf-8")
    p = load_profile(path)
    assert p.bed[1] == 500.0 and p.steps_per_mm == 5.0
    path.write_text("[limits]\ndraw_speed = 5000.0\n", encoding="utf-8")
    with pytest.raises(ProfileError, match=r"mine\.toml: limits\.draw_speed: must be <="):
        load_profile(path)


@pytest.mark.parametrize("overrides", [[], ["motion.dt=0.002"], ["motion.setpoints=adaptive"]])
def test_placement_has_none_of_grbls_own_limits(overrides):
    """On cae.json (faster than the machine) only the speed and acceleration limits slow a
    run: no look-ahead (which short lines would meet), junction or host-pause buffer (which
    adaptive lines would) of Grbl's."""
    tag = load_plan(CAE)
    setpoints = place(tag, load_profile(overrides=overrides).placement())
    limits = setpoints.limits
    assert limits["junction"] == limits["buffer"] == 1.0
    assert limits["segment"] <= max(limits["speed"], limits["acceleration"]) * 1.01
    for run in setpoints.runs:
        assert run.scale == pytest.approx(
            max(run.limits["speed"], run.limits["acceleration"]), rel=0.01
        )
        if not overrides:  # the fixed grid (a setpoint on the last one's step is left out)
            grid = np.diff(run.t)[:-1] / 0.025
            np.testing.assert_allclose(grid, np.round(grid), atol=1e-9)
            assert np.median(grid) == pytest.approx(1.0)


def test_the_board_holds_a_fifth_of_a_second_of_drawing_ahead():
    """One move executing and the FIFO's queued: a host late by less than 0.2 s (a busy
    desktop) never lets the board run dry, with moves short enough for a fast-changing run."""
    p = load_profile()
    assert p["motion.dt"] <= 0.025
    assert (p["serial.fifo"] + 1) * p["motion.dt"] >= 0.2
