"""Write and read sampled motion as CSV.

The file has the header ``t,x,y,vx,vy,speed,pen`` and one row per sample: time in seconds,
position and velocity in the tag's units (per second), speed, and ``pen`` as 0 (up) or 1 (down).
Floats are written with ``%.10g``.
"""

from __future__ import annotations

import io
import math
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from itertools import islice
from typing import Any, Protocol, TextIO

import numpy as np

from tagbot.errors import InputError

__all__ = ["HEADER", "MotionTable", "read_motion_csv", "write_motion_csv"]

HEADER = "t,x,y,vx,vy,speed,pen"
"""The exact first line of a motion CSV file."""

_COLUMNS = HEADER.split(",")
_ROW_FORMAT = "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%d\n"
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_CHUNK = 4096


class MotionLike(Protocol):
    """What :func:`write_motion_csv` needs: the sample arrays of a ``Motion``."""

    @property
    def t(self) -> np.ndarray: ...
    @property
    def xy(self) -> np.ndarray: ...
    @property
    def v(self) -> np.ndarray: ...
    @property
    def speed(self) -> np.ndarray: ...
    @property
    def pen(self) -> np.ndarray: ...


@dataclass(frozen=True, eq=False)
class MotionTable:
    """Samples read back from a motion CSV (a ``Motion`` without the ``plan`` column)."""

    t: np.ndarray
    """Sample times in seconds, shape (N,)."""
    xy: np.ndarray
    """Pen positions, shape (N, 2)."""
    v: np.ndarray
    """Velocities, shape (N, 2)."""
    speed: np.ndarray
    """Speeds, shape (N,)."""
    pen: np.ndarray
    """1 while the pen is down, 0 while lifted; int8, shape (N,)."""

    def __len__(self) -> int:
        return len(self.t)


def write_motion_csv(motion: MotionLike, dest: str | os.PathLike[str] | TextIO) -> None:
    """Write ``motion`` as CSV to a path or an open text file (which is left open)."""
    columns = _columns(motion)
    if isinstance(dest, str | os.PathLike):
        with open(dest, "w", encoding="utf-8", newline="") as f:
            _write_rows(f, columns)
    else:
        _write_rows(dest, columns)


def _columns(motion: MotionLike) -> list[np.ndarray]:
    """Return the seven CSV columns of ``motion``, checking shapes and finiteness."""
    t = np.asarray(motion.t, dtype=float)
    n = t.shape[0] if t.ndim == 1 else -1
    xy = np.asarray(motion.xy, dtype=float)
    v = np.asarray(motion.v, dtype=float)
    speed = np.asarray(motion.speed, dtype=float)
    pen = np.asarray(motion.pen)
    if n < 0 or xy.shape != (n, 2) or v.shape != (n, 2) or speed.shape != (n,) or pen.shape != (n,):
        raise ValueError(
            "motion: inconsistent shapes "
            f"t{t.shape} xy{xy.shape} v{v.shape} speed{speed.shape} pen{pen.shape}"
        )
    columns = [t, xy[:, 0], xy[:, 1], v[:, 0], v[:, 1], speed]
    for name, col in zip(_COLUMNS, columns, strict=False):
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            raise ValueError(f"motion: {name} is not finite at sample {bad[0]}: {col[bad[0]]!r}")
    columns.append(np.where(pen != 0, 1, 0))
    return columns


def _write_rows(f: TextIO, columns: list[np.ndarray]) -> None:
    f.write(HEADER + "\n")
    rows = zip(*(c.tolist() for c in columns), strict=True)
    while chunk := list(islice(rows, _CHUNK)):
        f.write("".join(_ROW_FORMAT % r for r in chunk))


def read_motion_csv(source: str | os.PathLike[str] | TextIO) -> MotionTable:
    """Read a motion CSV written by :func:`write_motion_csv`; problems raise InputError."""
    if isinstance(source, str | os.PathLike):
        name = os.fsdecode(source)
        from tagbot.inputs import read_input

        try:
            text = read_input(source).decode("utf-8")  # bounded, regular files only
        except UnicodeDecodeError as e:
            raise InputError(f"{name}: not UTF-8 text (byte {e.start})") from e
    else:
        name = getattr(source, "name", None) or "<motion>"
        text = source.read()
    return _parse(io.StringIO(text, newline=""), str(name))


def _parse(lines: Iterable[str], name: str) -> MotionTable:
    """Parse CSV lines into a MotionTable."""
    rows: list[list[float]] = []
    header_seen = False
    blank_at: int | None = None
    for lineno, raw in enumerate(lines, start=1):
        line = raw.rstrip("\r\n")
        if not header_seen:
            if line.startswith("\ufeff"):
                line = line[1:]
            if line.strip() != HEADER:
                raise InputError(f"{name}:{lineno}: expected header {HEADER!r}, got {_cut(line)}")
            header_seen = True
            continue
        if not line.strip():
            blank_at = blank_at or lineno
            continue
        if blank_at is not None:
            raise InputError(f"{name}:{blank_at}: blank line before the last sample")
        fields = line.split(",")
        if len(fields) != len(_COLUMNS):
            raise InputError(f"{name}:{lineno}: expected {len(_COLUMNS)} fields, got {len(fields)}")
        rows.append([_value(fields[j], col, name, lineno) for j, col in enumerate(_COLUMNS)])
        if len(rows) > 1 and not rows[-1][0] > rows[-2][0]:
            raise InputError(
                f"{name}:{lineno}: t: not increasing ({fields[0].strip()} after {rows[-2][0]!r})"
            )
    if not header_seen:
        raise InputError(f"{name}: empty (expected header {HEADER!r})")
    data = np.array(rows, dtype=float).reshape(-1, len(_COLUMNS))
    return MotionTable(
        t=data[:, 0].copy(),
        xy=data[:, 1:3].copy(),
        v=data[:, 3:5].copy(),
        speed=data[:, 5].copy(),
        pen=data[:, 6].astype(np.int8),
    )


def _value(field: str, column: str, name: str, lineno: int) -> float:
    """Parse one CSV field as a finite number (``pen``: 0 or 1)."""
    s = field.strip()
    if column == "pen":
        if s not in ("0", "1"):
            raise InputError(f"{name}:{lineno}: pen: expected 0 or 1, got {_cut(s)}")
        return float(s)
    if not _NUMBER.fullmatch(s):
        raise InputError(f"{name}:{lineno}: {column}: expected a finite number, got {_cut(s)}")
    x = float(s)
    if not math.isfinite(x):
        raise InputError(f"{name}:{lineno}: {column}: expected a finite number, got {_cut(s)}")
    return x


def _cut(s: Any, limit: int = 40) -> str:
    """Quote a field briefly for messages."""
    r = repr(s)
    return r if len(r) <= limit else r[: limit - 4] + "...'"
