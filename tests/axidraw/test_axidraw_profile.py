"""AxiDraw profiles: the makers' figures, the models, overrides and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.axidraw.profile import load_profile, packaged_profiles
from tagbot.errors import ProfileError


def test_packaged_models_have_their_travel():
    assert packaged_profiles() == ["default", "minikit", "sea3", "v3a3"]
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
