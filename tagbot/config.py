"""Layered TOML machine profiles: packaged defaults < a packaged profile or user file < overrides.

Shared by every machine (:mod:`tagbot.plotter.profile`, :mod:`tagbot.arm.profile`). A machine
describes its keys with a schema (section → key → kind) and ships ``profiles/default.toml`` plus
named profiles in its package; :func:`load_layered` merges ``default.toml``, then a packaged
profile by name or a user file by path, then ``key=value`` overrides (the value read as TOML,
falling back to a bare string: ``pen.type=z``). Every key must be known and every problem is one
line naming the file and the field, e.g. ``default.toml: bed.x_max: must be > bed.x_min``.

Kinds: ``NUMBER``, ``POSITIVE``, ``NON_NEGATIVE``, ``BOOL``, ``INT`` (positive integer),
``INTEGER`` (any integer), ``FIT_OR_POSITIVE`` (``"fit"`` or a number > 0), ``TEXT`` (a non-empty
string, e.g. a file name), or a tuple of the allowed strings.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from tagbot.errors import ProfileError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "BOOL",
    "FIT_OR_POSITIVE",
    "INT",
    "INTEGER",
    "NON_NEGATIVE",
    "NUMBER",
    "POSITIVE",
    "TEXT",
    "LayeredProfile",
    "ProfileError",
    "load_layered",
    "packaged_names",
]

NUMBER = "number"
POSITIVE = "positive"
NON_NEGATIVE = "non-negative"
BOOL = "bool"
INT = "positive integer"
INTEGER = "integer"
FIT_OR_POSITIVE = "fit or positive"
TEXT = "text"

Schema = Mapping[str, Mapping[str, Any]]
Layers = list[tuple[str, Mapping[str, Any]]]
"""The layers of a profile, first to last: ``(source, data)`` (a file's name or ``--set``)."""


@dataclass(frozen=True)
class LayeredProfile:
    """A merged, validated profile: ``values[section][key]`` and where each value came from."""

    values: Mapping[str, Mapping[str, Any]]
    sources: Mapping[str, str]
    """``"section.key"`` → the file (or ``--set``) that gave its value."""
    layers: tuple[str, ...] = ()
    """The sources, in the order they were applied."""

    def __getitem__(self, key: str) -> Any:
        section, name = key.split(".", 1)
        return self.values[section][name]

    def where(self, *keys: str) -> str:
        """The source that last set any of ``keys`` (for error messages)."""
        found = [self.sources[k] for k in keys if k in self.sources]
        order = {name: i for i, name in enumerate(self.layers)}
        return max(found, key=lambda name: order.get(name, -1)) if found else "profile"

    def need(self, ok: bool, keys: tuple[str, ...], message: str) -> None:
        """Raise ProfileError ``"<source>: <last key>: <message>"`` unless ``ok``."""
        if not ok:
            raise ProfileError(f"{self.where(*keys)}: {keys[-1]}: {message}")


P = TypeVar("P", bound=LayeredProfile)


def packaged_names(package: str) -> list[str]:
    """Names of the profiles shipped in ``<package>/profiles`` (``default``, ...)."""
    folder = resources.files(package) / "profiles"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_layered(
    cls: type[P],
    package: str,
    schema: Schema | Callable[[Layers], tuple[Schema, Layers]],
    profile: str | Path | None = None,
    overrides: Iterable[str] = (),
    check: Callable[[P], None] | None = None,
) -> P:
    """``default.toml`` of ``package``, then ``profile`` (packaged name or path), then overrides.

    ``schema`` may depend on the layers (a serial arm's joints are its description's): a
    function of the layers giving the schema and the layers to merge.
    Raises ProfileError naming the file and the field for unreadable files, unknown keys, values
    of the wrong kind, missing keys and (through ``check``) inconsistent values.
    """
    sources: dict[str, str] = {}
    layers: Layers = [_read_packaged(package, "default")]
    if profile is not None and str(profile) != "default":
        text = str(profile)
        if text in packaged_names(package) and not Path(text).exists():
            layers.append(_read_packaged(package, text))
        else:
            layers.append(_read_file(package, Path(text)))
    layers.append(("--set", _parse_overrides(overrides)))
    if callable(schema):
        schema, layers = schema(layers)
    values: dict[str, dict[str, Any]] = {section: {} for section in schema}
    for source, data in layers:
        _merge(schema, source, data, values, sources)
    for section, keys in schema.items():
        for key in keys:
            if key not in values[section]:
                last = next(reversed(sources.values()), "profile") if sources else "profile"
                raise ProfileError(f"{last}: {section}.{key}: missing")
    result = cls(values=values, sources=sources, layers=tuple(name for name, _ in layers))
    if check is not None:
        check(result)
    return result


def _read_packaged(package: str, name: str) -> tuple[str, dict[str, Any]]:
    resource = resources.files(package) / "profiles" / f"{name}.toml"
    label = f"{name}.toml"
    try:
        return label, tomllib.loads(resource.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ProfileError(f"{label}: not TOML ({e})") from e


def _read_file(package: str, path: Path) -> tuple[str, dict[str, Any]]:
    from tagbot.errors import InputError
    from tagbot.inputs import read_input

    label = str(path)
    if not path.exists():
        names = ", ".join(packaged_names(package))
        raise ProfileError(f"{label}: no such profile file (packaged profiles: {names})")
    try:
        text = read_input(path).decode("utf-8")  # bounded, regular files only
    except InputError as e:
        raise ProfileError(str(e)) from e
    except UnicodeDecodeError as e:
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
    schema: Schema,
    source: str,
    data: Mapping[str, Any],
    values: dict[str, dict[str, Any]],
    sources: dict[str, str],
) -> None:
    for section, table in data.items():
        if section not in schema:
            raise ProfileError(f"{source}: {section}: unknown section")
        if not isinstance(table, Mapping):
            raise ProfileError(f"{source}: {section}: must be a table")
        for key, value in table.items():
            field = f"{section}.{key}"
            if key not in schema[section]:
                raise ProfileError(f"{source}: {field}: unknown key")
            values[section][key] = convert(source, field, schema[section][key], value)
            sources[field] = source


def convert(source: str, field: str, kind: Any, value: Any) -> Any:
    """``value`` checked against ``kind`` (see the module docstring); ProfileError if it fails."""

    def fail(expected: str) -> ProfileError:
        return ProfileError(f"{source}: {field}: must be {expected}, got {value!r}")

    if isinstance(kind, tuple):
        if value not in kind:
            raise fail("one of " + ", ".join(kind))
        return value
    if kind == BOOL:
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if kind == TEXT:
        if not isinstance(value, str) or not value.strip():
            raise fail("a non-empty text")
        return value
    if kind == FIT_OR_POSITIVE and value == "fit":
        return value
    if kind in (INT, INTEGER):
        if isinstance(value, bool) or not isinstance(value, int) or (kind == INT and value <= 0):
            raise fail("a positive integer" if kind == INT else "an integer")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise fail('"fit" or a number' if kind == FIT_OR_POSITIVE else "a finite number")
    number = float(value)
    if kind in (POSITIVE, FIT_OR_POSITIVE) and number <= 0:
        raise fail("> 0")
    if kind == NON_NEGATIVE and number < 0:
        raise fail(">= 0")
    return number
