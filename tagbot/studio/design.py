"""The studio's editable design: plans being drawn, edit operations, undo/redo, and views.

A :class:`Design` is plain data (JSON-ready): the model, global Δt range, μ and σ, and a list of
draft plans, each with its targets, its strokes' parameters and the pen lift before it. A draft
may hold a single target (a plan being clicked into existence); every draft with two or more
targets is a :class:`~tagbot.model.plan.Plan`, and together they make the design's
:class:`~tagbot.model.plan.Tag` (:meth:`Design.tag`). Edits are :func:`apply` operations
(JSON objects, validated here) that either all succeed, giving a new design whose tag builds, or
raise :class:`StudioError` naming the operation and field; the old design is kept then.

All model maths (geometry, sampling, lognormals, fitting, variations) is tagbot's: this module
only edits parameters and asks the library for what the page draws (:func:`view`).
"""

from __future__ import annotations

import base64
import copy
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from tagbot.errors import PlanError, TagbotError
from tagbot.gesture.vary import in_order, lifts
from tagbot.io.planfile import json_kind
from tagbot.model.lognormal import lognormal
from tagbot.model.plan import DEFAULT_MU, DEFAULT_SIGMA, MODELS, Plan, Tag

__all__ = [
    "MAX_OPS",
    "MAX_PLANS",
    "MAX_TARGETS",
    "Design",
    "History",
    "StudioError",
    "apply",
    "design_from_tag",
    "empty_design",
    "view",
]

MAX_PLANS = 200
"""Plans a design may hold."""
MAX_TARGETS = 2000
"""Targets a design may hold, all plans together."""
MAX_OPS = 500
"""Operations in one edit request."""
MAX_COORD = 1e6
"""Largest coordinate accepted, in the tag's units."""
MAX_SECONDS = 60.0
"""Largest Δt, pen lift or start accepted, seconds."""
VIEW_DT = 0.005
"""Seconds between the trajectory samples the page draws."""
CURVE_POINTS = 36
"""Samples of each stroke's lognormal in the speed plot."""
PHI_LIMIT = math.pi - 1e-6
"""|φ| is kept below π (a ΣΛ* arc cannot turn further)."""

Design = dict[str, Any]
"""``{"model", "units", "dt_min", "dt_max", "mu", "sigma", "plans": [draft...], "gestures":
[[[x, y], ...], ...]}``; a draft is ``{"targets": [[x, y], ...], "strokes": [{"dt", "mu",
"sigma", "phi1", "phi2"}, ...], "lift": seconds}`` (``"start"`` on the first, ``"ink"`` on a
plan whose pen touches down or lifts off moving: :attr:`~tagbot.model.plan.Plan.ink`)."""


class StudioError(TagbotError, ValueError):
    """A request the studio refuses: the message names the field, e.g. ``ops[2].plan: ...``."""


def empty_design(model: str = "gamma", units: str = "mm") -> Design:
    """A design with no plans, the paper's μ and σ, and the fit's default Δt range."""
    return {
        "model": model,
        "units": units,
        "dt_min": 0.1,
        "dt_max": 0.35,
        "mu": DEFAULT_MU,
        "sigma": DEFAULT_SIGMA,
        "lift": 0.3,
        "plans": [],
        "gestures": [],
    }


def design_from_tag(tag: Tag, base: Design | None = None) -> Design:
    """A design holding ``tag``'s plans (each lift from the previous plan's lift-off to its
    touch-down, :func:`~tagbot.gesture.vary.lifts`); globals from ``base`` or the defaults,
    widened so that the tag's Δt fit in the range."""
    design = copy.deepcopy(base) if base is not None else empty_design()
    design["model"], design["units"] = tag.model, tag.units
    design["plans"] = []
    for plan, lift in zip(tag.plans, [0.0, *lifts(tag)], strict=True):
        design["plans"].append(_draft_of(plan, float(lift)))
    design["plans"][0]["start"] = float(tag.plans[0].start)
    inner = [float(v) for p in tag.plans for v in p.dt[1:]]
    if inner:
        design["dt_min"] = min(design["dt_min"], min(inner))
        design["dt_max"] = max(design["dt_max"], max(inner))
    mus = {float(v) for p in tag.plans for v in p.mu}
    sigmas = {float(v) for p in tag.plans for v in p.sigma}
    if len(mus) == 1:
        design["mu"] = mus.pop()
    if len(sigmas) == 1:
        design["sigma"] = sigmas.pop()
    return design


def _draft_of(plan: Plan, lift: float) -> dict[str, Any]:
    strokes = [
        {
            "dt": float(plan.dt[j]),
            "mu": float(plan.mu[j]),
            "sigma": float(plan.sigma[j]),
            "phi1": float(plan.phi1[j]),
            "phi2": float(plan.phi2[j]),
        }
        for j in range(plan.n_strokes)
    ]
    draft = {"targets": plan.targets.tolist(), "strokes": strokes, "lift": lift}
    if plan.ink is not None:  # the writer touched down or lifted off moving: kept through edits
        draft["ink"] = list(plan.ink)
    return draft


def tag_of(design: Design) -> Tag | None:
    """The design's tag (drafts with fewer than two targets left out), or None if it has none:
    each plan touches down its draft's ``lift`` after the previous one lifts off
    (:func:`~tagbot.gesture.vary.in_order`). Raises :class:`StudioError` when the parameters make
    no valid tag."""
    plans, gaps = [], []
    try:
        for k, draft in enumerate(design["plans"]):
            if len(draft["targets"]) < 2:
                continue
            s = draft["strokes"]
            try:
                plan = Plan(
                    draft["targets"],
                    [x["dt"] for x in s],
                    [x["mu"] for x in s],
                    [x["sigma"] for x in s],
                    [x["phi1"] for x in s],
                    [x["phi2"] for x in s],
                    float(draft.get("start", 0.0)) if not plans else 0.0,
                    draft.get("ink"),
                )
            except PlanError as e:
                raise StudioError(f"plans[{k}].{e}") from e
            if plans:
                gaps.append(float(draft["lift"]))
            plans.append(plan)
        if not plans:
            return None
        return in_order(plans, gaps, design["model"], design["units"])
    except PlanError as e:
        raise StudioError(str(e)) from e


class History:
    """The current design with undo and redo stacks; edits of one ``group`` (a drag) coalesce
    into one undo step."""

    LIMIT = 200

    def __init__(self, design: Design) -> None:
        self.design = design
        self.undo_stack: list[Design] = []
        self.redo_stack: list[Design] = []
        self.group: str | None = None
        self.version = 0

    def commit(self, design: Design, group: str | None = None) -> None:
        """Make ``design`` current; a new undo step unless ``group`` continues the last one."""
        if group is None or group != self.group:
            self.undo_stack.append(self.design)
            del self.undo_stack[: -self.LIMIT]
        self.redo_stack.clear()
        self.design, self.group = design, group
        self.version += 1

    def undo(self) -> bool:
        if not self.undo_stack:
            return False
        self.redo_stack.append(self.design)
        self.design, self.group = self.undo_stack.pop(), None
        self.version += 1
        return True

    def redo(self) -> bool:
        if not self.redo_stack:
            return False
        self.undo_stack.append(self.design)
        self.design, self.group = self.redo_stack.pop(), None
        self.version += 1
        return True


# --------------------------------------------------------------------------- validation


def number(value: Any, where: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """A finite JSON number within ``[lo, hi]``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise StudioError(f"{where}: expected a number, got {_kind(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise StudioError(f"{where}: must be finite, got {value!r}")
    if not lo <= x <= hi:
        raise StudioError(f"{where}: must be between {lo:g} and {hi:g}, got {x!r}")
    return x


def point(value: Any, where: str) -> list[float]:
    """A ``[x, y]`` pair of finite numbers within :data:`MAX_COORD`."""
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise StudioError(f"{where}: expected [x, y], got {_kind(value)}")
    return [number(c, f"{where}[{i}]", -MAX_COORD, MAX_COORD) for i, c in enumerate(value)]


def integer(value: Any, where: str, lo: int, hi: int) -> int:
    """A whole JSON number in ``[lo, hi]``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise StudioError(f"{where}: expected a whole number, got {_kind(value)}")
    if not lo <= value <= hi:
        raise StudioError(f"{where}: must be between {lo} and {hi}, got {value}")
    return value


def _kind(value: Any) -> str:
    return json_kind(value, quote_numbers=True)


# --------------------------------------------------------------------------- operations

STROKE_FIELDS = ("dt", "mu", "sigma", "phi1", "phi2", "phi")


def apply(design: Design, ops: Any) -> Design:
    """A copy of ``design`` with the operations ``ops`` applied in order (see the module
    docstring of :mod:`tagbot.studio.server` for each). Raises :class:`StudioError`."""
    return apply_ops(design, ops)[0]


def apply_ops(design: Design, ops: Any) -> tuple[Design, Tag | None]:
    """:func:`apply`, and the new design's tag (built to check it, so it is not built twice)."""
    if not isinstance(ops, list):
        raise StudioError(f"ops: expected a list of operations, got {_kind(ops)}")
    if len(ops) > MAX_OPS:
        raise StudioError(f"ops: at most {MAX_OPS} operations per request, got {len(ops)}")
    new = _copy(design)
    for i, op in enumerate(ops):
        where = f"ops[{i}]"
        if not isinstance(op, Mapping):
            raise StudioError(f"{where}: expected an object, got {_kind(op)}")
        name = op.get("op")
        handler = _OPS.get(name) if isinstance(name, str) else None
        if handler is None:
            known = ", ".join(sorted(_OPS))
            raise StudioError(f"{where}.op: unknown {name!r} (known: {known})")
        try:
            handler(new, op, where)
        except StudioError:
            raise
        except (KeyError, TypeError) as e:
            raise StudioError(f"{where}: malformed operation ({e})") from e
    _check_size(new)
    return new, tag_of(new)  # the parameters must make a tag


def _copy(design: Design) -> Design:
    """A copy to edit: plans deep, the faded gestures shared (no operation changes one)."""
    gestures = design["gestures"]
    copied = copy.deepcopy({k: v for k, v in design.items() if k != "gestures"})
    copied["gestures"] = list(gestures)
    return copied


def _check_size(design: Design) -> None:
    if len(design["plans"]) > MAX_PLANS:
        raise StudioError(f"plans: at most {MAX_PLANS} plans in a design")
    count = sum(len(p["targets"]) for p in design["plans"])
    if count > MAX_TARGETS:
        raise StudioError(f"targets: at most {MAX_TARGETS} targets in a design, got {count}")


def _plan(design: Design, op: Mapping[str, Any], where: str) -> dict[str, Any]:
    k = integer(op.get("plan"), f"{where}.plan", 0, max(len(design["plans"]) - 1, 0))
    if not design["plans"]:
        raise StudioError(f"{where}.plan: the design has no plans")
    return design["plans"][k]  # type: ignore[no-any-return]


def _stroke(design: Design, op: Mapping[str, Any], where: str) -> tuple[dict[str, Any], int]:
    draft = _plan(design, op, where)
    if not draft["strokes"]:
        raise StudioError(f"{where}.stroke: plans[{op['plan']}] has no strokes yet")
    j = integer(op.get("stroke"), f"{where}.stroke", 0, len(draft["strokes"]) - 1)
    return draft, j


def _new_stroke(design: Design, first: bool) -> dict[str, float]:
    """A new stroke (§5): Δt at mid-range (the first stroke of a plan at once), φ = 0."""
    mid = 0.5 * (design["dt_min"] + design["dt_max"])
    return {
        "dt": 0.0 if first else mid,
        "mu": design["mu"],
        "sigma": design["sigma"],
        "phi1": 0.0,
        "phi2": 0.0,
    }


def _op_move_target(design: Design, op: Mapping[str, Any], where: str) -> None:
    draft = _plan(design, op, where)
    i = integer(op.get("index"), f"{where}.index", 0, len(draft["targets"]) - 1)
    draft["targets"][i] = point(op.get("to"), f"{where}.to")


def _op_move_plan(design: Design, op: Mapping[str, Any], where: str) -> None:
    draft = _plan(design, op, where)
    dx, dy = point(op.get("by"), f"{where}.by")
    draft["targets"] = [[x + dx, y + dy] for x, y in draft["targets"]]
    for xy in draft["targets"]:
        point(xy, f"{where}.by")


def _angle(value: float) -> float:
    """``value`` wrapped to (−π, π]."""
    return math.atan2(math.sin(value), math.cos(value))


def _op_aim(design: Design, op: Mapping[str, Any], where: str) -> None:
    """Point a φ handle at ``toward``: the stroke's tangent at that end turns to it."""
    draft, j = _stroke(design, op, where)
    end = integer(op.get("end"), f"{where}.end", 1, 2)
    x, y = point(op.get("toward"), f"{where}.toward")
    (ax, ay), (bx, by) = draft["targets"][j], draft["targets"][j + 1]
    alpha = math.atan2(by - ay, bx - ax)
    # End 1: the stroke leaves target j towards the handle; end 2: it arrives at target j + 1
    # from the handle's side.
    tangent = math.atan2(y - ay, x - ax) if end == 1 else math.atan2(by - y, bx - x)
    if (x, y) == ((ax, ay) if end == 1 else (bx, by)):
        raise StudioError(f"{where}.toward: on the target itself (no direction)")
    phi = max(-PHI_LIMIT, min(PHI_LIMIT, _angle(tangent - alpha)))
    stroke = draft["strokes"][j]
    if design["model"] == "sigma":
        stroke["phi1"], stroke["phi2"] = (phi, -phi) if end == 1 else (-phi, phi)
    else:
        stroke["phi1" if end == 1 else "phi2"] = phi


def _op_set(design: Design, op: Mapping[str, Any], where: str) -> None:
    draft, j = _stroke(design, op, where)
    field = op.get("field")
    if field not in STROKE_FIELDS:
        raise StudioError(f"{where}.field: unknown {field!r} (known: {', '.join(STROKE_FIELDS)})")
    stroke = draft["strokes"][j]
    if field == "dt":
        stroke["dt"] = number(op.get("value"), f"{where}.value", 0.0, MAX_SECONDS)
    elif field == "mu":
        stroke["mu"] = number(op.get("value"), f"{where}.value", -10.0, 3.0)
    elif field == "sigma":
        stroke["sigma"] = number(op.get("value"), f"{where}.value", 1e-3, 3.0)
    else:
        phi = number(op.get("value"), f"{where}.value", -PHI_LIMIT, PHI_LIMIT)
        if field == "phi" or design["model"] == "sigma":
            sign = -1.0 if field == "phi1" else 1.0
            stroke["phi1"], stroke["phi2"] = -sign * phi, sign * phi
        else:
            stroke[field] = phi


def _op_dt_fraction(design: Design, op: Mapping[str, Any], where: str) -> None:
    """A Δt handle's length: Δt = Δt_min + fraction × (Δt_max − Δt_min)."""
    draft, j = _stroke(design, op, where)
    f = number(op.get("fraction"), f"{where}.fraction", 0.0, 1.0)
    lo, hi = design["dt_min"], design["dt_max"]
    draft["strokes"][j]["dt"] = hi if f == 1.0 else lo + f * (hi - lo)


def _op_insert(design: Design, op: Mapping[str, Any], where: str) -> None:
    """A new target at ``index`` (0 prepends, len appends; inside, it splits a stroke in two)."""
    draft = _plan(design, op, where)
    m = len(draft["targets"])
    i = integer(op.get("index"), f"{where}.index", 0, m)
    draft["targets"].insert(i, point(op.get("at"), f"{where}.at"))
    strokes = draft["strokes"]
    if m == 0:
        return
    if i == 0:
        strokes.insert(0, _new_stroke(design, first=True))
        if len(strokes) > 1:
            strokes[1]["dt"] = _new_stroke(design, first=False)["dt"]
    elif i == m:
        strokes.append(_new_stroke(design, first=len(strokes) == 0))
    else:  # stroke i − 1 becomes two straight halves of the same timing
        old = strokes[i - 1]
        strokes[i - 1] = {**old, "phi1": 0.0, "phi2": 0.0}
        strokes.insert(i, _new_stroke(design, first=False))


def _op_append(design: Design, op: Mapping[str, Any], where: str) -> None:
    draft = _plan(design, op, where)
    _op_insert(design, {**op, "index": len(draft["targets"])}, where)


def _op_delete(design: Design, op: Mapping[str, Any], where: str) -> None:
    """Delete a target; its strokes merge (an inner target) or go (an end); a plan left with no
    target is removed."""
    k = integer(op.get("plan"), f"{where}.plan", 0, max(len(design["plans"]) - 1, 0))
    draft = _plan(design, op, where)
    m = len(draft["targets"])
    i = integer(op.get("index"), f"{where}.index", 0, m - 1)
    del draft["targets"][i]
    strokes = draft["strokes"]
    if strokes:
        if i == 0:
            del strokes[0]
            if strokes:
                strokes[0]["dt"] = 0.0
        elif i == m - 1:
            del strokes[-1]
        else:  # strokes i − 1 and i merge: the earlier one's timing, the later one's end
            merged = {**strokes[i - 1], "phi2": strokes[i]["phi2"]}
            if design["model"] == "sigma":
                merged["phi2"] = -merged["phi1"]
            strokes[i - 1 : i + 1] = [merged]
    if not draft["targets"]:
        del design["plans"][k]


def _op_new_plan(design: Design, op: Mapping[str, Any], where: str) -> None:
    """A new plan holding one target (append targets to make strokes)."""
    draft: dict[str, Any] = {
        "targets": [point(op.get("at"), f"{where}.at")],
        "strokes": [],
        "lift": design["lift"],
    }
    if not design["plans"]:
        draft["start"] = 0.0
    design["plans"].append(draft)


def _op_delete_plan(design: Design, op: Mapping[str, Any], where: str) -> None:
    _plan(design, op, where)
    del design["plans"][op["plan"]]
    if design["plans"]:
        design["plans"][0].setdefault("start", 0.0)


def _op_lift(design: Design, op: Mapping[str, Any], where: str) -> None:
    _plan(design, op, where)["lift"] = number(op.get("seconds"), f"{where}.seconds", 0.02, 60)


def _op_globals(design: Design, op: Mapping[str, Any], where: str) -> None:
    """Δt_min/Δt_max (each Δt keeps its place in the range), μ and σ (set on every stroke), and
    the default pen lift."""
    known = {"op", "dt_min", "dt_max", "mu", "sigma", "lift"}
    extra = sorted(set(op) - known)
    if extra:
        raise StudioError(f"{where}.{extra[0]}: not a global (known: dt_min, dt_max, mu, sigma)")
    lo_old, hi_old = design["dt_min"], design["dt_max"]
    lo = number(op.get("dt_min", lo_old), f"{where}.dt_min", 0.0, MAX_SECONDS)
    hi = number(op.get("dt_max", hi_old), f"{where}.dt_max", 0.0, MAX_SECONDS)
    if hi < lo:
        raise StudioError(f"{where}.dt_max: must be >= dt_min ({lo:g}), got {hi:g}")
    if (lo, hi) != (lo_old, hi_old):
        for draft in design["plans"]:
            for s in draft["strokes"][1:]:
                f = 0.5 if hi_old == lo_old else (s["dt"] - lo_old) / (hi_old - lo_old)
                s["dt"] = lo + min(max(f, 0.0), 1.0) * (hi - lo)
        design["dt_min"], design["dt_max"] = lo, hi
    for name, lo_, hi_ in (("mu", -10.0, 3.0), ("sigma", 1e-3, 3.0)):
        if name in op:
            value = number(op[name], f"{where}.{name}", lo_, hi_)
            design[name] = value
            for draft in design["plans"]:
                for s in draft["strokes"]:
                    s[name] = value
    if "lift" in op:
        design["lift"] = number(op["lift"], f"{where}.lift", 0.02, MAX_SECONDS)


def _op_model(design: Design, op: Mapping[str, Any], where: str) -> None:
    """Switch model: a ΓΛ* stroke becomes the arc of its mean deviation ``(φ2 − φ1)/2``; a ΣΛ*
    arc is already a ΓΛ* stroke."""
    model = op.get("model")
    if model not in MODELS:
        raise StudioError(f"{where}.model: must be 'gamma' or 'sigma', got {_kind(model)}")
    if model == "sigma":
        for draft in design["plans"]:
            for s in draft["strokes"]:
                phi = max(-PHI_LIMIT, min(PHI_LIMIT, 0.5 * (s["phi2"] - s["phi1"])))
                s["phi1"], s["phi2"] = -phi, phi
    design["model"] = model


def _op_clear(design: Design, op: Mapping[str, Any], where: str) -> None:
    design["plans"], design["gestures"] = [], []


_OPS = {
    "aim": _op_aim,
    "append": _op_append,
    "clear": _op_clear,
    "delete": _op_delete,
    "delete_plan": _op_delete_plan,
    "dt_fraction": _op_dt_fraction,
    "globals": _op_globals,
    "insert": _op_insert,
    "lift": _op_lift,
    "model": _op_model,
    "move_plan": _op_move_plan,
    "move_target": _op_move_target,
    "new_plan": _op_new_plan,
    "set": _op_set,
}


# --------------------------------------------------------------------------- views


def pack(values: Any, dtype: str = "<f4") -> dict[str, Any]:
    """An array for the page: ``{"dtype", "b64"}``, its little-endian bytes in base64 (parsing
    thousands of JSON numbers per frame would cost more than the drawing)."""
    array = np.ascontiguousarray(values, dtype=dtype)
    return {"dtype": array.dtype.str, "b64": base64.b64encode(array.tobytes()).decode("ascii")}


def unpack(packed: Mapping[str, Any]) -> np.ndarray:
    """The array of :func:`pack`."""
    return np.frombuffer(base64.b64decode(packed["b64"]), dtype=packed["dtype"])


MAX_VIEW_SAMPLES = 20_000
"""The trajectory's step grows beyond :data:`VIEW_DT` to keep at most this many samples."""


def motion_view(tag: Tag, arrays: str = "packed") -> dict[str, Any]:
    """The trajectory the page draws: samples ``x, y, speed, pen`` of :meth:`Tag.sample` every
    ``dt`` from ``t0`` (:data:`VIEW_DT` s, finer if a pen lift is short, coarser if the tag is
    long); arrays :func:`pack`-ed, or JSON lists with ``arrays="json"`` (and ``t`` too)."""
    gaps = lifts(tag)
    dt = max(VIEW_DT, (tag.end - tag.start) / MAX_VIEW_SAMPLES)
    if gaps:
        dt = min(dt, max(min(gaps) / 2.5, 1e-4))
    motion = tag.sample(dt)
    columns = {"x": motion.xy[:, 0], "y": motion.xy[:, 1], "speed": motion.speed}
    out: dict[str, Any] = {"dt": dt, "n": len(motion.t), "t0": float(motion.t[0])}
    if arrays == "json":
        out |= {k: v.tolist() for k, v in columns.items()}
        out |= {"t": motion.t.tolist(), "pen": motion.pen.tolist()}
    else:  # sample i is at t0 + i·dt: no time column to send
        out |= {k: pack(v) for k, v in columns.items()} | {"pen": pack(motion.pen, "u1")}
    return out


def strokes_view(tag: Tag, design: Design, arrays: str = "packed") -> dict[str, Any]:
    """Per stroke (``items``): the tangent directions its φ handles show and its Δt's place in
    the design's range; and every stroke's lognormal ``D·Λ`` over its window, the speed plot's
    curves (``t`` and ``v``, :data:`CURVE_POINTS` per stroke, in stroke order)."""
    lo, hi = design["dt_min"], design["dt_max"]
    index = [k for k, d in enumerate(design["plans"]) if len(d["targets"]) >= 2]
    items, ts, vs = [], [], []
    grid = np.linspace(-1.0, 1.0, CURVE_POINTS) * math.sqrt(2.0 * math.log(1e3))
    for k, plan in zip(index, tag.plans, strict=True):
        alpha = np.arctan2(plan.chords[:, 1], plan.chords[:, 0])
        theta1, theta2 = (alpha + plan.phi1).tolist(), (alpha + plan.phi2).tolist()
        mu, sigma, t0 = plan.mu[:, None], plan.sigma[:, None], plan.onsets[:, None]
        t = t0 + np.exp(mu - sigma * sigma + sigma * grid)  # where Λ exceeds 1e-3 of its peak
        ts.append(t)
        vs.append(plan.geometry.length[:, None] * lognormal(t, t0, mu, sigma))
        span = hi - lo
        for j, dt in enumerate(plan.dt.tolist()):
            f = 0.5 if span == 0 else min(max((dt - lo) / span, 0.0), 1.0)
            items.append(
                {
                    "plan": k,
                    "stroke": j,
                    "theta1": theta1[j],
                    "theta2": theta2[j],
                    "dt": dt,
                    "dt_fraction": f,
                }
            )
    t, v = np.concatenate(ts).ravel(), np.concatenate(vs).ravel()
    if arrays == "json":
        return {"items": items, "points": CURVE_POINTS, "t": t.tolist(), "v": v.tolist()}
    return {"items": items, "points": CURVE_POINTS, "t": pack(t), "v": pack(v)}


def view(design: Design, tag: Tag | None = None, arrays: str = "packed") -> dict[str, Any]:
    """Everything the page draws for ``design`` (whose tag is ``tag`` when already built): the
    design itself, its tag as a plan file object (or None), the sampled trajectory, and each
    stroke's lognormal and handles."""
    from tagbot.io.planfile import tag_to_dict

    if tag is None:
        tag = tag_of(design)
    result: dict[str, Any] = {"design": design, "tag": None, "motion": None, "strokes": None}
    if tag is not None:
        result["tag"] = tag_to_dict(tag)
        result["motion"] = motion_view(tag, arrays)
        result["strokes"] = strokes_view(tag, design, arrays)
        result["duration"] = float(tag.end - tag.start)
    return result
