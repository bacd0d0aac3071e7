"""Arm profiles: layering (defaults < file < overrides) and one-line validation errors."""

from __future__ import annotations

import math

import pytest

from tagbot.arm import ProfileError, load_profile, packaged_profiles
from tagbot.arm.profile import SCHEMA
from tagbot.errors import TagbotError


def test_packaged_defaults() -> None:
    profile = load_profile()
    assert profile.links == (150.0, 150.0)
    assert profile["motion.rate"] == 100.0 and profile.period == pytest.approx(0.01)
    assert profile["bus.baud"] == 1_000_000
    assert profile.servos == {1: "XM430-W350", 2: "XM430-W350", 3: "XL430-W250"}
    assert profile.names == {1: "shoulder", 2: "elbow", 3: "pen"}
    assert profile.profile_ms == 20 and profile.lead == pytest.approx(0.02)
    assert profile.readback_every == 1
    assert profile["motion.time_scale"] == "run" and profile["motion.trim_ticks"] == 1.0
    assert profile["motion.max_deviation"] == 0.15
    shoulder, elbow = profile.joints
    assert shoulder.model_number == 1020 and elbow.lower == pytest.approx(math.radians(10))
    assert "default" in packaged_profiles()
    for section, keys in SCHEMA.items():
        for key in keys:
            profile[f"{section}.{key}"]  # every key has a packaged default


def test_layering_order(tmp_path) -> None:
    user = tmp_path / "mine.toml"
    user.write_text("[arm]\nl1 = 160.0\n[motion]\nrate = 200\n", encoding="utf-8")
    profile = load_profile(user, ["arm.l1=170", "bus.readback_rate=50"])
    assert profile["arm.l1"] == 170.0 and profile.sources["arm.l1"] == "--set"
    assert profile["motion.rate"] == 200.0 and profile.sources["motion.rate"] == str(user)
    assert profile.readback_every == 4 and profile.period == pytest.approx(0.005)
    assert profile["arm.l2"] == 150.0 and profile.sources["arm.l2"] == "default.toml"


@pytest.mark.parametrize(
    ("text", "overrides", "message"),
    [
        ("[elbow]\nmax_deg = 5.0\n", [], "{f}: elbow.max_deg: must be > elbow.min_deg"),
        ("[arm]\nreach = 3\n", [], "{f}: arm.reach: unknown key"),
        ("[wrist]\nid = 4\n", [], "{f}: wrist: unknown section"),
        ("[pen]\nid = 1\n", [], "{f}: pen.id: IDs must differ"),
        ("[pen]\nid = 253\n", [], "{f}: pen.id: must be a DYNAMIXEL ID 0..252, got 253"),
        ('[pen]\nmodel = "XM540"\n', [], "{f}: pen.model: must be one of XL430-W250, XM430-W350"),
        ("[shoulder]\nsign = 2\n", [], "{f}: shoulder.sign: must be 1 or -1, got 2"),
        ("[shoulder]\nmax_deg = 300.0\n", [], "{f}: shoulder.max_deg: 300° is 4437 ticks, outside"),
        (
            "",
            ["elbow.min_deg=-20"],
            "--set: elbow.max_deg: the elbow range -20..160° must lie within 0..180°",
        ),
        (
            "",
            ["arm.elbow=negative"],
            "--set: elbow.max_deg: the elbow range 10..160° must lie within -180..0°",
        ),
        (
            "",
            ["motion.park_elbow=170"],
            "--set: motion.park_elbow: outside elbow.min_deg..elbow.max_deg",
        ),
        ("", ["servo.profile_ms=40000"], "--set: servo.profile_ms: must be <= 32737 ms"),
        ("", ["motion.rate=1000"], "--set: motion.rate: must be <= 500 Hz, got 1000"),
        ("", ["bus.baud=9600"], "--set: bus.baud: must be one of 57600"),
        ("", ["bus.return_delay_us=3"], "--set: bus.return_delay_us: must be an even number of µs"),
        ("", ["bus.readback_rate=200"], "--set: bus.readback_rate: must be <= motion.rate"),
        ("", ["pen.up=2048"], "--set: pen.up: must differ from pen.down"),
        (
            "",
            ["motion.time_scale=fast"],
            "--set: motion.time_scale: must be one of run, uniform, got 'fast'",
        ),
        ("", ["motion.trim_ticks=-1"], "--set: motion.trim_ticks: must be >= 0, got -1"),
        (
            "",
            ["servo.acceleration_fraction=0.6"],
            "--set: servo.acceleration_fraction: must be <= 0.5",
        ),
        ("", ["area.margin=200"], "--set: area.margin: leaves no room in the area"),
        ("", ["arm.l1=-1"], "--set: arm.l1: must be > 0, got -1"),
        ("", ["place.scale=big"], "--set: place.scale: must be \"fit\" or a number, got 'big'"),
        (
            "",
            ["servo.profile_ms=5"],
            "--set: servo.profile_ms: must be >= the period (10 ms at 100 Hz)",
        ),
        ("x = [", [], "{f}: not TOML"),
    ],
)
def test_validation_errors(tmp_path, text: str, overrides: list[str], message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ProfileError) as raised:
        load_profile(path, overrides)
    assert str(raised.value).startswith(message.format(f=path))
    assert "\n" not in str(raised.value)
    assert isinstance(raised.value, ValueError) and isinstance(raised.value, TagbotError)


def test_missing_file_names_packaged_profiles(tmp_path) -> None:
    with pytest.raises(ProfileError, match=r"no such profile file .*packaged profiles: default"):
        load_profile(tmp_path / "nope.toml")
