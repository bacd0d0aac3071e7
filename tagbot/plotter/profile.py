"""Machine profiles: TOML files layered as packaged defaults < user file < ``key=value`` overrides.

:func:`load_profile` starts from the packaged ``profiles/default.toml``, then applies a packaged
profile by name (``"zpen"``) or a user file by path, then overrides such as ``"bed.margin=5"``
(the value is read as TOML, falling back to a bare string: ``pen.type=z``). Every key must be
known; every problem is one line naming the file and the field, e.g.
``default.toml: bed.x_max: must be > bed.x_min``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from tagbot.errors import TagbotError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["SCHEMA", "Profile", "ProfileError", "load_profile", "packaged_profiles"]


class ProfileError(TagbotError, ValueError):
    """A machine profile is unreadable or invalid; the message names the file and the field."""


_NUMBER = "number"
_POSITIVE = "positive"
_NON_NEGATIVE = "non-negative"
_BOOL = "bool"
_INT = "positive integer"

ALIGNS = ("center", "bottom-left", "bottom-right", "top-left", "top-right")
PEN_TYPES = ("servo", "z")

SCHEMA: dict[str, dict[str, Any]] = {
    "bed": {
        "x_min": _NUMBER,
        "x_max": _NUMBER,
        "y_min": _NUMBER,
        "y_max": _NUMBER,
        "margin": _NON_NEGATIVE,
        "y_down": _BOOL,
    },
    "limits": {
        "from_device": _BOOL,
        "x_max_feed": _POSITIVE,
        "y_max_feed": _POSITIVE,
        "x_acceleration": _POSITIVE,
        "y_acceleration": _POSITIVE,
        "junction_deviation": _POSITIVE,
        "x_steps_per_mm": _POSITIVE,
        "min_feed": _POSITIVE,
        "slowest_step": _POSITIVE,
        "y_steps_per_mm": _POSITIVE,
        "planner_blocks": _INT,
    },
    "pen": {
        "type": PEN_TYPES,
        "up": _NUMBER,
        "down": _NUMBER,
        "dwell": _NON_NEGATIVE,
        "feed": _POSITIVE,
    },
    "motion": {
        "dt": _POSITIVE,
        "travel_feed": _POSITIVE,
        "park": _BOOL,
        "park_x": _NUMBER,
        "park_y": _NUMBER,
    },
    "place": {
        "scale": "fit or positive",
        "rotation": _NUMBER,
        "align": ALIGNS,
    },
    "serial": {"baud": _INT},
}
"""Every section and key a profile may hold, with the kind of value it takes."""


@dataclass(frozen=True)
class Profile:
    """A merged, validated profile: ``values[section][key]`` and where each value came from."""

    values: Mapping[str, Mapping[str, Any]]
    sources: Mapping[str, str]
    """``"section.key"`` → the file (or ``--set``) that gave its value."""
    layers: tuple[str, ...] = ()
    """The sources, in the order they were applied."""

    def __getitem__(self, key: str) -> Any:
        section, name = key.split(".", 1)
        return self.values[section][name]

    @property
    def bed(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` in mm."""
        b = self.values["bed"]
        return b["x_min"], b["x_max"], b["y_min"], b["y_max"]

    @property
    def max_speed(self) -> tuple[float, float]:
        """Per-axis speed limits, mm/s."""
        return self["limits.x_max_feed"] / 60.0, self["limits.y_max_feed"] / 60.0

    @property
    def max_acceleration(self) -> tuple[float, float]:
        """Per-axis acceleration limits, mm/s²."""
        return self["limits.x_acceleration"], self["limits.y_acceleration"]

    @property
    def dt(self) -> float:
        return self["motion.dt"]

    def where(self, *keys: str) -> str:
        """The source that last set any of ``keys`` (for error messages)."""
        found = [self.sources[k] for k in keys if k in self.sources]
        order = {name: i for i, name in enumerate(self.layers)}
        return max(found, key=lambda name: order.get(name, -1)) if found else "profile"


def packaged_profiles() -> list[str]:
    """Names of the profiles shipped with tagbot (``default``, ``zpen``...)."""
    folder = resources.files("tagbot.plotter") / "profiles"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_profile(profile: str | Path | None = None, overrides: Iterable[str] = ()) -> Profile:
    """Packaged defaults, then ``profile`` (a packaged name or a TOML path), then ``overrides``.

    Raises ProfileError naming the file and the field for unreadable files, unknown keys, values
    of the wrong kind and inconsistent values (e.g. ``bed.x_max`` not above ``bed.x_min``).
    """
    values: dict[str, dict[str, Any]] = {section: {} for section in SCHEMA}
    sources: dict[str, str] = {}
    layers = [_read_packaged("default")]
    if profile is not None and str(profile) != "default":
        text = str(profile)
        if text in packaged_profiles() and not Path(text).exists():
            layers.append(_read_packaged(text))
        else:
            layers.append(_read_file(Path(text)))
    layers.append(("--set", _parse_overrides(overrides)))
    for source, data in layers:
        _merge(source, data, values, sources)
    for section, keys in SCHEMA.items():
        for key in keys:
            if key not in values[section]:
                raise ProfileError(f"{source_of(sources)}: {section}.{key}: missing")
    result = Profile(values=values, sources=sources, layers=tuple(name for name, _ in layers))
    _check(result)
    return result


def source_of(sources: Mapping[str, str]) -> str:
    return next(reversed(sources.values()), "profile") if sources else "profile"


def _read_packaged(name: str) -> tuple[str, dict[str, Any]]:
    resource = resources.files("tagbot.plotter") / "profiles" / f"{name}.toml"
    label = f"{name}.toml"
    try:
        return label, tomllib.loads(resource.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ProfileError(f"{label}: not TOML ({e})") from e


def _read_file(path: Path) -> tuple[str, dict[str, Any]]:
    label = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        names = ", ".join(packaged_profiles())
        raise ProfileError(f"{label}: no such profile file (packaged profiles: {names})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ProfileError(f"{label}: cannot read ({e})") from e
    try:
        return label, tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ProfileError(f"{label}: not TOML ({e})") from e


def _parse_overrides(overrides: Iterable[str]) -> dict[str, Any]:
    data: dict[str, Any] = {}
    for item in overrides:
        key, sep, raw = str(item).partition("=")
        key = key.strip()
        if not sep or "." not in key:
            raise ProfileError(f"--set: {item!r}: expected section.key=value, e.g. bed.margin=5")
        try:
            value = tomllib.loads(f"v = {raw.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw.strip()
        section, name = key.split(".", 1)
        data.setdefault(section, {})[name] = value
    return data


def _merge(
    source: str,
    data: Mapping[str, Any],
    values: dict[str, dict[str, Any]],
    sources: dict[str, str],
) -> None:
    for section, table in data.items():
        if section not in SCHEMA:
            raise ProfileError(f"{source}: {section}: unknown section")
        if not isinstance(table, Mapping):
            raise ProfileError(f"{source}: {section}: must be a table")
        for key, value in table.items():
            field = f"{section}.{key}"
            if key not in SCHEMA[section]:
                raise ProfileError(f"{source}: {field}: unknown key")
            values[section][key] = _convert(source, field, SCHEMA[section][key], value)
            sources[field] = source


def _convert(source: str, field: str, kind: Any, value: Any) -> Any:
    def fail(expected: str) -> ProfileError:
        return ProfileError(f"{source}: {field}: must be {expected}, got {value!r}")

    if isinstance(kind, tuple):
        if value not in kind:
            raise fail("one of " + ", ".join(kind))
        return value
    if kind == _BOOL:
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if kind == "fit or positive" and value == "fit":
        return value
    if kind == _INT:
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise fail("a positive integer")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise fail('"fit" or a number' if kind == "fit or positive" else "a finite number")
    number = float(value)
    if kind in (_POSITIVE, "fit or positive") and number <= 0:
        raise fail("> 0")
    if kind == _NON_NEGATIVE and number < 0:
        raise fail(">= 0")
    return number


def _check(p: Profile) -> None:
    """Checks across fields; the error names the source that last set one of them."""

    def need(ok: bool, keys: tuple[str, ...], message: str) -> None:
        if not ok:
            raise ProfileError(f"{p.where(*keys)}: {keys[-1]}: {message}")

    x_min, x_max, y_min, y_max = p.bed
    need(x_max > x_min, ("bed.x_min", "bed.x_max"), "must be > bed.x_min")
    need(y_max > y_min, ("bed.y_min", "bed.y_max"), "must be > bed.y_min")
    margin = p["bed.margin"]
    need(
        2 * margin < min(x_max - x_min, y_max - y_min),
        ("bed.margin",),
        "leaves no room on the bed",
    )
    need(p.dt <= 1.0, ("motion.dt",), "must be <= 1 s (one G-code line per step)")
    # F = 60/dt must fit Grbl's 8 digits at 3 decimals; Grbl cannot parse lines faster anyway.
    need(p.dt >= 0.001, ("motion.dt",), "must be >= 0.001 s (F = 60/dt needs <= 8 digits)")
    if p["motion.park"]:
        need(
            x_min <= p["motion.park_x"] <= x_max,
            ("bed.x_min", "bed.x_max", "motion.park_x"),
            "outside the bed",
        )
        need(
            y_min <= p["motion.park_y"] <= y_max,
            ("bed.y_min", "bed.y_max", "motion.park_y"),
            "outside the bed",
        )
    if p["pen.type"] == "servo":
        need(p["pen.up"] >= 0, ("pen.up",), "must be >= 0 (an M3 S value)")
        need(p["pen.down"] >= 0, ("pen.down",), "must be >= 0 (an M3 S value)")
    else:
        need(p["pen.up"] > p["pen.down"], ("pen.down", "pen.up"), "must be > pen.down (Z up)")
