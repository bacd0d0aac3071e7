"""Read and write tag plans as versioned JSON files.

A plan file holds one :class:`~tagbot.model.plan.Tag`::

    {"format": "tagbot-plan", "version": 1, "model": "gamma", "units": "mm",
     "plans": [{"start": 0.0, "targets": [[x, y], ...],
                "strokes": [{"dt": .., "mu": .., "sigma": .., "phi1": .., "phi2": ..}, ...]}]}

Sigma-model strokes carry one ``"phi"`` instead of ``"phi1"``/``"phi2"``. A plan whose pen touches
down or lifts off while moving has ``"ink": [down, up]`` (seconds after its start; see
:attr:`~tagbot.model.plan.Plan.ink`); a file with such a plan is version 2, so that a tagbot that
reads only version 1 refuses it rather than ink the air. Unknown extra fields are ignored.
Every problem raises :class:`~tagbot.errors.PlanFileError` with a one-line message that
names the offending field as a path, e.g. ``plans[0].strokes[1].mu: missing``. Numbers are written
with ``repr`` so a saved tag loads back bit-exactly.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from tagbot.errors import PlanFileError
from tagbot.io.output import write_atomic
from tagbot.model.plan import Plan, Tag

__all__ = [
    "FORMAT",
    "VERSION",
    "load_plan",
    "plan_bytes",
    "save_plan",
    "tag_from_dict",
    "tag_to_dict",
]

FORMAT = "tagbot-plan"
"""Value of the ``"format"`` marker field."""

VERSION = 2
"""The newest version this tagbot reads and writes (1 when no plan has an ``ink`` window)."""
VERSIONS = (1, 2)
"""The only plan file version this tagbot reads and writes."""


_STROKE_FIELDS = {
    "gamma": ("dt", "mu", "sigma", "phi1", "phi2"),
    "sigma": ("dt", "mu", "sigma", "phi"),
}


# --------------------------------------------------------------------------- reading


def load_plan(path: str | os.PathLike[str]) -> Tag:
    """Read a plan file and return its :class:`Tag`; every problem raises PlanFileError."""
    name = os.fsdecode(path)
    from tagbot.errors import InputError
    from tagbot.inputs import read_input

    try:
        raw = read_input(path)  # bounded, regular files only
    except InputError as e:
        raise PlanFileError(str(e)) from (e.__cause__ or e)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise PlanFileError(f"{name}: not JSON (not UTF-8 text at byte {e.start})") from e
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise PlanFileError(f"{name}: not JSON (line {e.lineno}, column {e.colno}: {e.msg})") from e
    except RecursionError as e:
        raise PlanFileError(f"{name}: not JSON (nested too deeply)") from e
    except ValueError as e:  # an integer with more digits than Python parses
        raise PlanFileError(f"{name}: not JSON ({e})") from e
    try:
        return tag_from_dict(data)
    except PlanFileError as e:
        raise PlanFileError(f"{name}: {e}") from e


def tag_from_dict(d: Any) -> Tag:
    """Build a :class:`Tag` from parsed plan-file JSON; every problem raises PlanFileError."""
    if not isinstance(d, Mapping):
        raise PlanFileError(f"expected a JSON object at the top level, got {json_kind(d)}")
    fmt = _field(d, "format", "")
    if fmt != FORMAT:
        raise PlanFileError(f'format: expected "{FORMAT}", got {_show(fmt)}')
    version = _field(d, "version", "")
    if type(version) is not int or version not in VERSIONS:
        raise PlanFileError(f"version: unsupported {_show(version)} (this tagbot reads 1 and 2)")
    model = _field(d, "model", "")
    if not isinstance(model, str) or model not in _STROKE_FIELDS:
        raise PlanFileError(f'model: unknown {_show(model)} (expected "gamma" or "sigma")')
    units = _field(d, "units", "")
    if not isinstance(units, str):
        raise PlanFileError(f"units: expected a string, got {_show(units)}")
    raw_plans = _field(d, "plans", "")
    if not isinstance(raw_plans, list):
        raise PlanFileError(f"plans: expected a list of plans, got {json_kind(raw_plans)}")
    if not raw_plans:
        raise PlanFileError("plans: empty")

    plans = [_plan_from_dict(p, f"plans[{k}]", model, version) for k, p in enumerate(raw_plans)]
    try:
        return Tag(plans, model=model, units=units)
    except ValueError as e:
        raise PlanFileError(str(e)) from (e.__cause__ or e)


def _plan_from_dict(p: Any, path: str, model: str, version: int) -> Plan:
    """Validate one plan object's structure and construct the Plan."""
    if not isinstance(p, Mapping):
        raise PlanFileError(f"{path}: expected an object, got {json_kind(p)}")
    start = _number(_field(p, "start", path), f"{path}.start")
    ink = None
    if "ink" in p:
        if version < 2:
            raise PlanFileError(f"{path}.ink: needs a version 2 plan file, this one is version 1")
        raw = p["ink"]
        if not isinstance(raw, list) or len(raw) != 2:
            raise PlanFileError(f"{path}.ink: expected [down, up] seconds, got {_show(raw)}")
        ink = (_number(raw[0], f"{path}.ink[0]"), _number(raw[1], f"{path}.ink[1]"))

    raw_targets = _field(p, "targets", path)
    if not isinstance(raw_targets, list):
        got = json_kind(raw_targets)
        raise PlanFileError(f"{path}.targets: expected a list of [x, y], got {got}")
    targets = [_point(xy, f"{path}.targets[{i}]") for i, xy in enumerate(raw_targets)]
    if len(targets) < 2:
        raise PlanFileError(f"{path}.targets: need at least 2, got {len(targets)}")

    raw_strokes = _field(p, "strokes", path)
    if not isinstance(raw_strokes, list):
        got = json_kind(raw_strokes)
        raise PlanFileError(f"{path}.strokes: expected a list of strokes, got {got}")
    if len(raw_strokes) != len(targets) - 1:
        raise PlanFileError(
            f"{path}.strokes: expected {len(targets) - 1} strokes for {len(targets)} targets, "
            f"got {len(raw_strokes)}"
        )
    names = _STROKE_FIELDS[model]
    columns: dict[str, list[float]] = {name: [] for name in names}
    for i, s in enumerate(raw_strokes):
        spath = f"{path}.strokes[{i}]"
        if not isinstance(s, Mapping):
            raise PlanFileError(f"{spath}: expected an object, got {json_kind(s)}")
        for name in names:
            if name not in s:
                raise PlanFileError(f"{spath}.{name}: missing{_model_hint(model, name, s)}")
            columns[name].append(_number(s[name], f"{spath}.{name}"))

    xy = np.array(targets, dtype=float).reshape(-1, 2)
    arrays = {name: np.array(values, dtype=float) for name, values in columns.items()}
    try:
        if model == "sigma":
            return Plan.sigma_model(xy, start=start, ink=ink, **arrays)
        return Plan(xy, start=start, ink=ink, **arrays)
    except ValueError as e:
        msg = str(e)
        raise PlanFileError(msg if msg.startswith("plans[") else f"{path}.{msg}") from e


def _field(d: Mapping[str, Any], name: str, path: str) -> Any:
    """Return ``d[name]`` or raise ``<path>.<name>: missing``."""
    if name not in d:
        raise PlanFileError(f"{path + '.' if path else ''}{name}: missing")
    return d[name]


def _number(v: Any, path: str) -> float:
    """Return a JSON number as a finite float (bools are not numbers)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise PlanFileError(f"{path}: expected a number, got {_show(v)}")
    try:
        x = float(v)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise PlanFileError(f"{path}: must be finite, got {_show(v)}")
    return x


def _point(v: Any, path: str) -> tuple[float, float]:
    """Return a JSON ``[x, y]`` pair of finite numbers."""
    if (
        not isinstance(v, list)
        or len(v) != 2
        or any(isinstance(c, bool) or not isinstance(c, int | float) for c in v)
    ):
        raise PlanFileError(f"{path}: expected [x, y] numbers, got {_show(v)}")
    try:
        x, y = float(v[0]), float(v[1])
    except OverflowError:
        x = y = math.inf
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlanFileError(f"{path}: must be finite, got {_show(v)}")
    return x, y


def _model_hint(model: str, name: str, stroke: Mapping[str, Any]) -> str:
    """Explain a phi/phi1/phi2 mix-up between the two models."""
    if model == "sigma" and name == "phi" and ("phi1" in stroke or "phi2" in stroke):
        return ' (sigma-model strokes have one "phi"; "phi1"/"phi2" are for model "gamma")'
    if model == "gamma" and name in ("phi1", "phi2") and "phi" in stroke:
        return ' (gamma-model strokes have "phi1" and "phi2"; one "phi" is for model "sigma")'
    return ""


def json_kind(v: Any, quote_numbers: bool = False) -> str:
    """Name a JSON value's type for messages (a number as itself with ``quote_numbers``)."""
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, int | float):
        return repr(v) if quote_numbers else "a number"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, Mapping):
        return "an object"
    return type(v).__name__


def _show(v: Any, limit: int = 40) -> str:
    """Render a JSON value briefly, on one line, for messages."""
    try:
        s = json.dumps(v, ensure_ascii=True)
    except (TypeError, ValueError):
        s = repr(v)
    return s if len(s) <= limit else s[: limit - 3] + "..."


# --------------------------------------------------------------------------- writing


def tag_to_dict(tag: Tag) -> dict[str, Any]:
    """Return the plan-file JSON object for ``tag`` (numbers as Python floats)."""
    model = tag.model
    plans = []
    for k, plan in enumerate(tag.plans):
        path = f"plans[{k}]"
        targets = np.asarray(plan.targets, dtype=float)
        columns: dict[str, list[float]] = {
            "dt": np.asarray(plan.dt, dtype=float).tolist(),
            "mu": np.asarray(plan.mu, dtype=float).tolist(),
            "sigma": np.asarray(plan.sigma, dtype=float).tolist(),
        }
        phi1 = np.asarray(plan.phi1, dtype=float)
        phi2 = np.asarray(plan.phi2, dtype=float)
        if model == "sigma":
            bad = np.flatnonzero(phi1 != -phi2)
            if bad.size:
                raise PlanFileError(
                    f"{path}.strokes[{bad[0]}]: sigma model needs phi1 == -phi2, "
                    f"got {phi1[bad[0]]!r} and {phi2[bad[0]]!r}"
                )
            columns["phi"] = phi2.tolist()
        else:
            columns["phi1"] = phi1.tolist()
            columns["phi2"] = phi2.tolist()
        names = _STROKE_FIELDS[model]
        plans.append(
            {
                "start": float(plan.start),
                **({"ink": list(plan.ink)} if plan.ink is not None else {}),
                "targets": targets.tolist(),
                "strokes": [
                    {name: columns[name][i] for name in names} for i in range(len(columns["dt"]))
                ],
            }
        )
    return {
        "format": FORMAT,
        "version": VERSION if any(plan.ink is not None for plan in tag.plans) else 1,
        "model": model,
        "units": tag.units,
        "plans": plans,
    }


def save_plan(tag: Tag, path: str | os.PathLike[str]) -> None:
    """Write ``tag`` to ``path`` as a plan file, atomically (temp file + ``os.replace``)."""
    write_atomic(path, plan_bytes(tag))


def plan_bytes(tag: Tag) -> bytes:
    """The bytes :func:`save_plan` writes for ``tag`` (UTF-8 JSON, one final newline)."""
    return (_dumps(tag_to_dict(tag)) + "\n").encode("utf-8")


def _dumps(v: Any, indent: str = "") -> str:
    """Pretty but compact JSON: containers of scalars on one line, floats via ``repr``."""
    if isinstance(v, Mapping):
        items = list(v.items())
        if all(_is_scalar(x) for _, x in items):
            return "{" + ", ".join(f"{json.dumps(k)}: {_scalar(x)}" for k, x in items) + "}"
        inner = indent + "  "
        body = ",\n".join(f"{inner}{json.dumps(k)}: {_dumps(x, inner)}" for k, x in items)
        return "{\n" + body + "\n" + indent + "}"
    if isinstance(v, list | tuple):
        if all(_is_scalar(x) for x in v):
            return "[" + ", ".join(_scalar(x) for x in v) + "]"
        inner = indent + "  "
        body = ",\n".join(f"{inner}{_dumps(x, inner)}" for x in v)
        return "[\n" + body + "\n" + indent + "]"
    return _scalar(v)


def _is_scalar(v: Any) -> bool:
    return v is None or isinstance(v, str | int | float)


def _scalar(v: Any) -> str:
    """One JSON scalar; floats use ``repr`` (shortest round-trip form), never NaN/Infinity."""
    if isinstance(v, float) and not math.isfinite(v):
        raise PlanFileError(f"cannot save a non-finite number ({v!r})")
    return json.dumps(v, allow_nan=False)
