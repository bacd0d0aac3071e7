"""Read point files: CSV and JSON lists of pen-down points.

Coordinates are taken as they are (any unit, y up: no flip, no scaling); coordinates and times
must be finite numbers of magnitude at most 10¹⁵. Times are seconds on the
file's clock; each trace's ``t`` is shifted so that the file's first point is at 0, keeping the
gaps between traces. Times must be finite and must not decrease through the file (a decrease is
an error naming the line or item); if all times are equal the file is untimed (``t`` None).

**CSV.** Fields are separated by commas, or by semicolons, tabs or spaces when the first line
has no comma (then ``0,5`` is a decimal comma). Lines starting with ``#`` are comments. A first line
holding anything that is not a number is a header: it must name columns ``x`` and ``y``, and may
name ``t`` (or ``time``, seconds), ``pen`` (1 down, 0 up) and ``stroke`` (or ``trace``: an id;
a new value starts a new trace); other columns are ignored, so tagbot's own motion CSV
(``t,x,y,vx,vy,speed,pen``) reads as its pen-down runs. Without a header, rows hold 2 or 3
numbers: ``x, y`` or ``x, y, t``. A blank line ends the current trace; rows with pen 0 end it too
and are dropped.

**JSON.** ``[[x, y], ...]`` is one trace, ``[[[x, y], ...], ...]`` several, and
``{"traces": [{"xy": [[x, y], ...], "t": [t0, ...]}, ...]}`` several with optional times (all
traces or none). Empty traces are skipped; JSONP ``callback(...)`` is accepted.
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from tagbot.errors import InputError
from tagbot.inputs._common import (
    MAX_MAGNITUDE,
    check_size,
    cut,
    decode_text,
    make_trace,
    parse_json,
    parse_number,
)
from tagbot.inputs.trace import Trace

__all__ = ["looks_like_csv", "read_points_csv", "read_points_json", "read_points_json_object"]

_ALIASES = {
    "x": "x",
    "y": "y",
    "t": "t",
    "time": "t",
    "pen": "pen",
    "stroke": "stroke",
    "trace": "stroke",
}
"""Header names (case-insensitive) → the column they stand for."""


# --------------------------------------------------------------------------- CSV


def looks_like_csv(text: str) -> bool:
    """Whether ``text`` starts like a point CSV (a header naming x and y, or 2–3 numbers)."""
    for raw in text[:65536].splitlines()[:64]:
        line = raw.strip().lstrip("\ufeff")
        if not line or line.startswith("#"):
            continue
        sep = _separator(line)
        fields = _split(line, sep)
        if all(parse_number(f, sep != ",") is not None for f in fields):
            return len(fields) in (2, 3)
        names = [_ALIASES.get(f.lower()) for f in fields]
        return "x" in names and "y" in names
    return False


def read_points_csv(data: bytes, name: str = "<csv>") -> list[Trace]:
    """Read a CSV point file; see the module doc. Problems raise InputError naming the line."""
    check_size(data, name)
    text = decode_text(data, name, "point file")
    rows: list[list[float]] = []  # x, y, t
    breaks: list[int] = []  # row indices where a new trace starts
    columns: dict[str, int] | None = None
    sep: str | None = ","
    width = 0
    t_prev: tuple[float, int] | None = None
    last_stroke: str | None = None
    new_trace = True
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if lineno == 1:
            line = line.lstrip("\ufeff")
        if line.startswith("#"):
            continue
        if not line:
            new_trace = True
            continue
        if columns is None:
            sep = _separator(line)
            columns, width, is_header = _columns(line, sep, name, lineno)
            if is_header:
                continue
        fields = _split(line, sep)
        if len(fields) != width:
            raise InputError(f"{name}: line {lineno}: expected {width} fields, got {len(fields)}")
        values = {}
        for col, j in columns.items():
            if col == "stroke":
                continue
            v = parse_number(fields[j], sep != ",")
            if v is None:
                raise InputError(f"{name}: line {lineno}: {col} is not a number ({cut(fields[j])})")
            if abs(v) > MAX_MAGNITUDE:
                raise InputError(
                    f"{name}: line {lineno}: {col} is out of range ({cut(fields[j])}; "
                    f"at most {MAX_MAGNITUDE:g} in magnitude)"
                )
            values[col] = v
        if "pen" in values:
            if values["pen"] not in (0.0, 1.0):
                raise InputError(
                    f"{name}: line {lineno}: pen is not 0 or 1 ({cut(fields[columns['pen']])})"
                )
            if values["pen"] == 0.0:
                new_trace = True
                continue
        if "stroke" in columns:
            stroke = fields[columns["stroke"]]
            if stroke != last_stroke:
                new_trace = True
            last_stroke = stroke
        if "t" in values:
            if t_prev is not None and values["t"] < t_prev[0]:
                raise InputError(
                    f"{name}: line {lineno}: t decreases ({fields[columns['t']]} after "
                    f"{t_prev[0]!r} on line {t_prev[1]})"
                )
            t_prev = (values["t"], lineno)
        if new_trace:
            breaks.append(len(rows))
            new_trace = False
        rows.append([values["x"], values["y"], values.get("t", 0.0)])
    if not rows:
        raise InputError(f"{name}: no points")
    table = np.array(rows, dtype=np.float64)
    times = table[:, 2] if columns and "t" in columns else None
    return _traces(name, table[:, :2], times, breaks)


def _separator(line: str) -> str | None:
    """The field separator: ``,``, else ``;`` or tab, else None (runs of spaces)."""
    for sep in (",", ";", "\t"):
        if sep in line:
            return sep
    return None


def _split(line: str, sep: str | None) -> list[str]:
    return [f.strip().strip('"').strip() for f in line.split(sep)]


def _columns(
    line: str, sep: str | None, name: str, lineno: int
) -> tuple[dict[str, int], int, bool]:
    """Column indices from the first row, its field count, and whether it is a header."""
    fields = _split(line, sep)
    if all(parse_number(f, sep != ",") is not None for f in fields):
        if len(fields) not in (2, 3):
            raise InputError(
                f"{name}: line {lineno}: expected 2 or 3 numbers (x, y[, t]) without a header, "
                f"got {len(fields)} fields"
            )
        return dict(zip(("x", "y", "t"), range(len(fields)), strict=False)), len(fields), False
    columns: dict[str, int] = {}
    for j, field in enumerate(fields):
        col = _ALIASES.get(field.lower())
        if col is not None:
            if col in columns:
                raise InputError(f"{name}: line {lineno}: column {col} appears twice")
            columns[col] = j
    missing = [c for c in ("x", "y") if c not in columns]
    if missing:
        raise InputError(
            f"{name}: line {lineno}: header has no {' or '.join(missing)} column "
            f"(got {cut(line, 60)})"
        )
    return columns, len(fields), True


# --------------------------------------------------------------------------- JSON


def read_points_json(data: bytes, name: str = "<json>") -> list[Trace]:
    """Read a JSON point file; see the module doc. Problems raise InputError naming the item."""
    check_size(data, name)
    return read_points_json_object(parse_json(decode_text(data, name, "point file"), name), name)


def read_points_json_object(obj: object, name: str) -> list[Trace]:
    """Read already parsed point JSON (a list, or an object with ``"traces"``)."""
    items: list[tuple[str, str, object, object]] = []  # (xy path, t path, xy, t)
    if isinstance(obj, dict):
        traces = obj.get("traces")
        if not isinstance(traces, list):
            raise InputError(f'{name}: traces: expected a list of {{"xy": [...]}} objects')
        for k, tr in enumerate(traces):
            if not isinstance(tr, dict) or "xy" not in tr:
                raise InputError(f'{name}: traces[{k}]: expected an object with "xy"')
            items.append((f"traces[{k}].xy", f"traces[{k}].t", tr["xy"], tr.get("t")))
    elif isinstance(obj, list):
        if obj and isinstance(obj[0], list) and obj[0] and not isinstance(obj[0][0], list):
            items.append(("", "", obj, None))  # [[x, y], ...]: one trace
        else:
            items.extend((f"[{k}]", "", tr, None) for k, tr in enumerate(obj))
    else:
        raise InputError(f'{name}: expected a list of points, of traces, or {{"traces": ...}}')
    timed = [t is not None for *_, t in items]
    if any(timed) and not all(timed):
        raise InputError(
            f"{name}: {items[timed.index(False)][1]}: missing while other traces have times"
        )
    xys: list[np.ndarray] = []
    ts: list[np.ndarray] = []
    prev_end: tuple[float, str] | None = None
    for xy_path, t_path, xy, t in items:
        points = _points(xy, xy_path, name)
        if not len(points):
            continue
        if t is not None:
            times = _times(t, len(points), t_path, name)
            if prev_end is not None and times[0] < prev_end[0]:
                raise InputError(f"{name}: {t_path}: starts before {prev_end[1]} ends")
            prev_end = (float(times[-1]), t_path)
            ts.append(times)
        xys.append(points)
    if not xys:
        raise InputError(f"{name}: no points")
    breaks = np.cumsum([0] + [len(p) for p in xys[:-1]]).tolist()
    return _traces(name, np.concatenate(xys), np.concatenate(ts) if ts else None, breaks)


def _points(xy: object, path: str, name: str) -> np.ndarray:
    if not isinstance(xy, list):
        raise InputError(f"{name}: {path or 'top level'}: expected a list of [x, y] points")
    out = np.empty((len(xy), 2), dtype=np.float64)
    for i, p in enumerate(xy):
        x = y = None
        if isinstance(p, list) and len(p) == 2:
            x, y = _json_number(p[0]), _json_number(p[1])
        if x is None or y is None:
            raise InputError(
                f"{name}: {path}[{i}]: expected [x, y] finite numbers (at most "
                f"{MAX_MAGNITUDE:g} in magnitude), got {cut(p)}"
            )
        out[i] = x, y
    return out


def _json_number(v: object) -> float | None:
    """A JSON number (not a string, not a boolean) within MAX_MAGNITUDE, else None."""
    x = None if isinstance(v, str) else parse_number(v, False)
    return x if x is not None and abs(x) <= MAX_MAGNITUDE else None


def _times(t: object, n: int, path: str, name: str) -> np.ndarray:
    if not isinstance(t, list) or len(t) != n:
        size = f"{len(t)} times" if isinstance(t, list) else cut(t)
        raise InputError(f"{name}: {path}: expected a list of {n} times, got {size}")
    out = np.empty(n, dtype=np.float64)
    for i, v in enumerate(t):
        x = _json_number(v)
        if x is None:
            raise InputError(
                f"{name}: {path}[{i}]: expected a finite number (at most {MAX_MAGNITUDE:g} in "
                f"magnitude), got {cut(v)}"
            )
        if i and x < out[i - 1]:
            raise InputError(
                f"{name}: {path}[{i}]: time decreases ({x!r} after {float(out[i - 1])!r})"
            )
        out[i] = x
    return out


# --------------------------------------------------------------------------- shared


def _traces(name: str, xy: np.ndarray, t: np.ndarray | None, breaks: list[int]) -> list[Trace]:
    """Split the file's points at ``breaks``; times shifted to start at 0, None if constant."""
    if t is not None:
        t = t - t[0]
        if t[-1] <= 0:
            t = None
    bounds = [*breaks, len(xy)]
    return [
        make_trace(name, xy[a:b], None if t is None else t[a:b])
        for a, b in pairwise(bounds)
        if b > a
    ]
