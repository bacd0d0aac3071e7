"""Machine profiles: layering (defaults < file < overrides) and one-line validation errors."""

from __future__ import annotations

import pytest

from tagbot.errors import TagbotError
from tagbot.plotter import ProfileError, load_profile
from tagbot.plotter.profile import SCHEMA, packaged_profiles


def test_packaged_defaults():
    profile = load_profile()
    assert profile["motion.dt"] == 0.01
    assert profile["serial.baud"] == 115200
    assert profile["limits.planner_blocks"] == 15
    assert profile["limits.from_device"] is False
    assert profile["pen.type"] == "servo"
    assert profile["motion.time_scale"] == "run"
    assert profile["motion.setpoints"] == "adaptive"
    assert profile["motion.trim"] is True
    assert profile["motion.slow_lines"] == "clamp"
    assert profile["motion.tolerance"] == 0.02
    assert profile["motion.max_dt"] == 0.25
    assert profile["motion.min_buffer"] == 0.6
    assert profile.sources["bed.x_max"] == "default.toml"
    assert set(packaged_profiles()) >= {"default", "zpen"}
    for section, keys in SCHEMA.items():
        for key in keys:
            profile[f"{section}.{key}"]  # every key has a packaged default


def test_layering_order(tmp_path):
    user = tmp_path / "mine.toml"
    user.write_text("[bed]\nmargin = 3.0\nx_max = 300\n[pen]\ndwell = 0.3\n", encoding="utf-8")
    profile = load_profile(user, ["bed.margin=7", "pen.type=z", "pen.up=5", "pen.down=0"])
    assert profile["bed.margin"] == 7.0 and profile.sources["bed.margin"] == "--set"
    assert profile["bed.x_max"] == 300.0 and profile.sources["bed.x_max"] == str(user)
    assert profile["pen.dwell"] == 0.3
    assert profile["pen.type"] == "z"
    assert profile["bed.y_max"] == 297.0  # from the packaged defaults


def test_packaged_zpen():
    profile = load_profile("zpen")
    assert profile["pen.type"] == "z" and profile["pen.up"] > profile["pen.down"]
    assert profile.sources["pen.type"] == "zpen.toml"
    assert profile["bed.x_max"] == 420.0


@pytest.mark.parametrize(
    ("text", "overrides", "message"),
    [
        ("[bed]\nx_max = -1.0\n", [], "{f}: bed.x_max: must be > bed.x_min"),
        ("[bed]\nwidth = 3\n", [], "{f}: bed.width: unknown key"),
        ("[bead]\nx_max = 3\n", [], "{f}: bead: unknown section"),
        ("[limits]\nx_acceleration = 0\n", [], "{f}: limits.x_acceleration: must be > 0, got 0"),
        (
            "[limits]\nplanner_blocks = 1.5\n",
            [],
            "{f}: limits.planner_blocks: must be a positive integer, got 1.5",
        ),
        ('[pen]\ntype = "laser"\n', [], "{f}: pen.type: must be one of servo, z, got 'laser'"),
        ("[motion]\npark = 1\n", [], "{f}: motion.park: must be true or false, got 1"),
        ("[bed]\nmargin = 200.0\n", [], "{f}: bed.margin: leaves no room on the bed"),
        ("[motion]\npark_x = 999.0\n", [], "{f}: motion.park_x: outside the bed"),
        ("", ["bed.y_min=400"], "--set: bed.y_max: must be > bed.y_min"),
        ("", ["place.scale=big"], "--set: place.scale: must be \"fit\" or a number, got 'big'"),
        ("", ["margin=3"], "--set: 'margin=3': expected section.key=value, e.g. bed.margin=5"),
        ("", ["bed.colour=red"], "--set: bed.colour: unknown key"),
        ("x = [", [], "{f}: not TOML"),
        ("", ["motion.dt=0.0005"], "--set: motion.dt: must be >= 0.001 s"),
        ("[motion]\ndt = 2\n", [], "{f}: motion.dt: must be <= 1 s"),
        ("", ["motion.max_dt=0.005"], "--set: motion.max_dt: must be >= motion.dt"),
        ("", ["motion.max_dt=3"], "--set: motion.max_dt: must be <= 2 s"),
        (
            "",
            ["motion.time_scale=global"],
            "--set: motion.time_scale: must be one of run, uniform, got 'global'",
        ),
        ("", ["motion.tolerance=0"], "--set: motion.tolerance: must be > 0, got 0"),
        ("", ["motion.min_buffer=-1"], "--set: motion.min_buffer: must be >= 0, got -1"),
        ("[pen]\ntype = 'z'\nup = 0\ndown = 1\n", [], "{f}: pen.up: must be > pen.down"),
    ],
)
def test_validation_errors(tmp_path, text, overrides, message):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ProfileError) as raised:
        load_profile(path, overrides)
    assert str(raised.value).startswith(message.format(f=path))
    assert "\n" not in str(raised.value)
    assert isinstance(raised.value, ValueError) and isinstance(raised.value, TagbotError)


def test_missing_file_names_packaged_profiles(tmp_path):
    with pytest.raises(ProfileError, match=r"no such profile file \(packaged profiles: default"):
        load_profile(tmp_path / "nope.toml")


def test_override_values_are_toml():
    profile = load_profile(None, ["bed.y_down=true", "place.scale=2", "place.align=top-left"])
    assert profile["bed.y_down"] is True
    assert profile["place.scale"] == 2.0
    assert profile["place.align"] == "top-left"
