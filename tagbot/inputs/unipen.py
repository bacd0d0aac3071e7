"""Read UNIPEN files: the online-handwriting format of the UNIPEN benchmarks (UNIPEN 1.0).

A UNIPEN file is lines of keywords (a ``.`` in the first column, e.g. ``.COORD X Y``) each
followed by its arguments; everything else is ignored. The rules, from the format definition
(``unipen.def``, I. Guyon 1994) and the NIST train_r01_v07 distribution:

**Pen data.** ``.PEN_DOWN`` and ``.PEN_UP`` start a component whose samples follow, one per line
(numbers on the keyword's own line count too). Each ``.PEN_DOWN`` component becomes one trace;
``.PEN_UP`` components (the pen moving in the air) only advance the clock. ``.COORD`` names the
columns (``X`` and ``Y`` required, ``T`` optional, others such as ``P`` or ``Z`` ignored); a
sample line must then hold exactly that many numbers. Without ``.COORD`` a line holds ``x y``
and possibly more numbers, which are ignored. Numbers are decimal (no ``nan``, ``inf``, hex or
digit separators) of magnitude at most 10¹⁵, as in every tagbot reader.

**Units.** ``.X_POINTS_PER_MM`` and ``.Y_POINTS_PER_MM`` (or ``..._PER_INCH``) turn the
coordinates into millimetres; when only one axis is given it is used for both, and without
either the coordinates are kept in the file's own unit (as point files are). The y axis points
up, as in UNIPEN's own viewer (upview draws ``maxy - y``) and the NICI tablet data, which writes
negated screen rows so that words read upright.

**Timing.** With ``T`` in ``.COORD`` a sample's time is T, in milliseconds (the format's unit),
and must not decrease through the file. Otherwise ``.POINTS_PER_SECOND`` (the sampling rate)
gives sample k of the file, pen-up samples included, the time k / rate: a pen lift keeps its
real duration, in-air samples counting in the clock. ``.DT`` (time elapsed while samples were
elided, read as milliseconds like T; not a component) is added. Times are shifted so the first
pen-down point is at 0; without T or a rate the traces are untimed.

**Segments.** ``.SEGMENT`` lines (e.g. ``.SEGMENT WORD 0-14 OK "abdomen"``) are listed by
:func:`parse_unipen` and :meth:`UnipenFile.traces` reads one of them: components are numbered
from 0 in order (empty ones are not counted; ``.START_SET`` restarts the count) and delineations
follow the ``[A[:M]]-[B[:N]],[C]`` notation (component A from point M to component B point N,
then component C); a selection is refused when several ``.START_SET`` hold components, each
numbered from 0. Loading a whole file reads every pen-down component.

**Untrusted input.** ``.INCLUDE`` is never followed: a file whose pen data lives in an included
file is refused, naming it, so that it can be read directly. Files are at most 32 MB with at most
:data:`MAX_POINTS` samples; every problem is one line naming the file and the line.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from tagbot.errors import InputError
from tagbot.inputs._common import (
    MAX_MAGNITUDE,
    check_size,
    cut,
    decode_text,
    make_trace,
    parse_number,
    read_input,
)
from tagbot.inputs.trace import Trace

__all__ = [
    "MAX_POINTS",
    "MAX_RATE",
    "Segment",
    "UnipenFile",
    "load_unipen",
    "looks_like_unipen",
    "parse_unipen",
    "read_unipen",
]

MAX_POINTS = 5_000_000
"""Most samples (pen-down and pen-up) a UNIPEN file may hold."""

MAX_RATE = 1e6
"""Highest ``.POINTS_PER_SECOND`` accepted (a megahertz: no pen is sampled faster)."""

_KEYWORD = re.compile(r"\.[A-Za-z_][A-Za-z0-9_]*")

_PEN = {".PEN_DOWN": True, ".PEN_UP": False}

_RESOLUTION = {
    ".X_POINTS_PER_MM": ("x", 1.0),
    ".Y_POINTS_PER_MM": ("y", 1.0),
    ".X_POINTS_PER_INCH": ("x", 25.4),
    ".Y_POINTS_PER_INCH": ("y", 25.4),
}
"""Resolution keywords → (axis, millimetres per the keyword's length unit)."""

_HEADER = frozenset({".COORD", ".POINTS_PER_SECOND", ".DT", ".INCLUDE", ".SEGMENT", *_RESOLUTION})
"""Keywords whose arguments are read (others, such as .COMMENT or .LEXICON, are skipped)."""

_LABEL = re.compile(r'"((?:[^"\\]|\\.)*)"', re.DOTALL)

_RANGE = re.compile(r"(\d*)(?::(\d+))?(?:-(\d*)(?::(\d+))?)?")


@dataclass(frozen=True)
class Segment:
    """A ``.SEGMENT`` line: its type, delineation, quality and label (None when omitted)."""

    kind: str
    components: str | None
    quality: str | None
    label: str | None
    line: int


@dataclass(frozen=True)
class _Component:
    down: bool
    start: int
    """Index of the component's first sample among the file's samples."""
    size: int
    line: int


@dataclass(frozen=True, eq=False)
class UnipenFile:
    """A parsed UNIPEN file: its samples, pen components and segments (see the module doc)."""

    name: str
    xy: np.ndarray
    """Every sample (pen-down and pen-up), shape (N, 2), in mm (or the file's unit)."""
    ticks: np.ndarray | None
    """Each sample's time before scaling: an index on the sampling clock, or T in ms."""
    lapse: np.ndarray | None
    """Milliseconds elided by ``.DT`` before each sample (sampling clock only)."""
    rate: float | None
    """Samples per second of the sampling clock, None when the times are the T column."""
    components: tuple[_Component, ...]
    sets: int
    """How many separately numbered sets of components (``.START_SET``) hold pen data."""
    segments: tuple[Segment, ...] = ()
    includes: tuple[str, ...] = ()
    clock: str | None = None

    def traces(self, components: str | None = None) -> list[Trace]:
        """One trace per pen-down component, or per pen-down run of the selected ``components``
        (a delineation such as ``"0-14"`` or ``"1:40-3,5"``); times share the file's clock."""
        if not any(c.down for c in self.components):
            if self.includes:
                raise InputError(
                    f"{self.name}: no pen data here; it includes {self.includes[0]!r}, which "
                    "tagbot does not follow (untrusted input): read that file instead"
                )
            what = "only .PEN_UP samples" if self.components else "no .PEN_DOWN samples"
            raise InputError(f"{self.name}: no points ({what})")
        keep = None if components is None else self._select(components)
        runs: list[tuple[int, int]] = []
        for c in self.components:
            if not c.down:
                continue
            if keep is None:
                runs.append((c.start, c.start + c.size))
                continue
            inside = np.flatnonzero(keep[c.start : c.start + c.size])
            if inside.size:  # maximal runs of selected points
                cuts = np.flatnonzero(np.diff(inside) > 1) + 1
                for part in np.split(inside, cuts):
                    runs.append((c.start + int(part[0]), c.start + int(part[-1]) + 1))
        if not runs:  # only when a selection misses every pen-down sample
            raise InputError(f"{self.name}: no points (components {components!r} are all pen-up)")
        t = self._times(runs[0][0])
        if t is not None and t[runs[-1][1] - 1] <= 0:
            t = None  # all at one instant
        return [
            make_trace(self.name, self.xy[a:b], None if t is None else t[a:b], self.clock)
            for a, b in runs
        ]

    def _times(self, first: int) -> np.ndarray | None:
        """Seconds of every sample, zero at sample ``first``; None if untimed."""
        if self.ticks is None:
            return None
        if self.rate is None:
            t = (self.ticks - self.ticks[first]) / 1000.0
        else:
            assert self.lapse is not None
            t = (self.ticks - self.ticks[first]) / self.rate
            if self.lapse[-1]:
                t = t + (self.lapse - self.lapse[first]) / 1000.0
        if not np.all(np.abs(t) <= MAX_MAGNITUDE):
            raise InputError(f"{self.name}: times beyond {MAX_MAGNITUDE:g} s")
        return t

    def _select(self, spec: str) -> np.ndarray:
        """A mask of the samples a delineation selects."""
        numbered = self.components
        if self.sets > 1:
            raise InputError(
                f"{self.name}: components {spec!r} are ambiguous: the file has {self.sets} sets"
                " (.START_SET), each numbering its components from 0"
            )
        keep = np.zeros(len(self.xy), dtype=bool)
        n = len(numbered)
        for item in spec.split(","):
            m = _RANGE.fullmatch(item.strip())
            if not item.strip() or m is None or (m[2] and m.group(3) is None):
                raise InputError(
                    f"{self.name}: components {spec!r}: {item!r} is not A, A-B or A[:M]-B[:N]"
                )
            ranged = m.group(3) is not None
            a = int(m[1]) if m[1] else 0
            b = (int(m[3]) if m[3] else n - 1) if ranged else a
            for k in (a, b):
                if k >= n:
                    raise InputError(
                        f"{self.name}: components {spec!r}: component {k} does not exist (the "
                        f"file has {n}, numbered from 0)"
                    )
            if b < a:
                raise InputError(f"{self.name}: components {spec!r}: {item!r} runs backwards")
            first, last = numbered[a], numbered[b]
            lo = first.start + self._point(m[2], first, spec, 0)
            hi = last.start + self._point(m[4], last, spec, last.size - 1)
            if hi < lo:
                raise InputError(f"{self.name}: components {spec!r}: {item!r} runs backwards")
            keep[lo : hi + 1] = True
        return keep

    def _point(self, text: str | None, c: _Component, spec: str, default: int) -> int:
        if not text:
            return default
        k = int(text)
        if k >= c.size:
            raise InputError(
                f"{self.name}: components {spec!r}: point {k} is beyond the {c.size} points of"
                f" the component on line {c.line}"
            )
        return k


def looks_like_unipen(text: str) -> bool:
    """Whether ``text`` starts like a UNIPEN file: its first non-blank line is a ``.KEYWORD``."""
    for raw in text[:65536].splitlines()[:64]:
        line = raw.strip().lstrip("\ufeff")
        if line:
            word = line.split(None, 1)[0]
            return _KEYWORD.fullmatch(word) is not None
    return False


def load_unipen(path: str | os.PathLike[str], components: str | None = None) -> list[Trace]:
    """Read a UNIPEN file's traces (all pen-down components, or the ``components`` selected)."""
    return read_unipen(read_input(path), os.fsdecode(path), components)


def read_unipen(data: bytes, name: str = "<unipen>", components: str | None = None) -> list[Trace]:
    """Read the traces of a UNIPEN file's bytes; see :func:`load_unipen` and the module doc."""
    return parse_unipen(data, name).traces(components)


def parse_unipen(data: bytes, name: str = "<unipen>") -> UnipenFile:
    """Parse a UNIPEN file's bytes (pen data, units, clock, segments); problems raise
    :class:`~tagbot.errors.InputError` naming the line."""
    check_size(data, name)
    return _Parser(name).run(decode_text(data, name, "UNIPEN file"))


class _Parser:
    """One pass over the lines; pen samples are gathered in flat lists."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.x: list[float] = []
        self.y: list[float] = []
        self.t: list[float] = []
        self.lapse: list[float] = []
        self.dt = 0.0
        self.coord: tuple[str, ...] | None = None
        self.columns = (0, 1, None)  # x, y, t
        self.per_mm: dict[str, tuple[float, int]] = {}
        self.rate: tuple[float, int] | None = None
        self.components: list[_Component] = []
        self.resets: set[int] = set()
        """Component counts at which a ``.START_SET`` restarted the numbering."""
        self.segments: list[Segment] = []
        self.includes: list[str] = []
        self.t_prev: tuple[float, int] | None = None

    def fail(self, lineno: int, message: str) -> InputError:
        return InputError(f"{self.name}: line {lineno}: {message}")

    def run(self, text: str) -> UnipenFile:
        keyword: str | None = None
        args: list[str] = []
        line0 = 0
        pen: tuple[bool, int, int] | None = None  # down, first sample, line
        for lineno, raw in enumerate(text.splitlines(), start=1):
            if raw[:1] == "." and _KEYWORD.match(raw):
                if keyword is not None:
                    self.header(keyword, " ".join(args), line0)
                    keyword = None
                if pen is not None:
                    self.close(pen)
                    pen = None
                word, *tail = raw.split(None, 1)
                rest = tail[0] if tail else ""
                if word in _PEN:
                    pen = (_PEN[word], len(self.x), lineno)
                    if rest.strip():
                        self.sample(rest, lineno)
                elif word == ".START_SET":
                    self.resets.add(len(self.components))
                elif word in _HEADER:
                    keyword, args, line0 = word, [rest], lineno
                continue
            if pen is not None:
                if raw.strip():
                    self.sample(raw, lineno)
            elif keyword is not None:
                args.append(raw)
        if keyword is not None:
            self.header(keyword, " ".join(args), line0)
        if pen is not None:
            self.close(pen)
        return self.finish()

    # ----------------------------------------------------------------- keywords

    def header(self, keyword: str, arg: str, lineno: int) -> None:
        if keyword == ".SEGMENT":
            self.segments.append(self.segment(arg, lineno))
        elif keyword == ".INCLUDE":
            if arg.split():
                self.includes.append(arg.split()[0])
        elif keyword == ".DT":
            value = self.number(arg, keyword, lineno)
            if value < 0:
                raise self.fail(lineno, f".DT is negative ({cut(arg.strip())})")
            self.dt += value
        elif keyword == ".COORD":
            self.declare_coord(arg, lineno)
        else:
            value = self.number(arg, keyword, lineno)
            if not value > 0:
                raise self.fail(lineno, f"{keyword} must be positive (got {cut(arg.strip())})")
            if keyword == ".POINTS_PER_SECOND":
                if value > MAX_RATE:
                    raise self.fail(
                        lineno, f".POINTS_PER_SECOND {value:g} is above {MAX_RATE:g} samples/s"
                    )
                self.redeclare(self.rate, value, keyword, lineno)
                self.rate = (value, lineno)
            else:
                axis, mm = _RESOLUTION[keyword]
                per_mm = value / mm
                if not per_mm >= 1 / MAX_MAGNITUDE:
                    raise self.fail(lineno, f"{keyword} {value:g} is too small")
                self.redeclare(self.per_mm.get(axis), per_mm, keyword, lineno)
                self.per_mm[axis] = (per_mm, lineno)

    def redeclare(self, old: tuple[float, int] | None, value: float, kw: str, lineno: int) -> None:
        """A unit or rate may be repeated, but not changed once samples were read."""
        if old is not None and old[0] != value and self.x:
            raise self.fail(
                lineno, f"{kw} changes after pen data (was {old[0]:g} on line {old[1]})"
            )

    def number(self, arg: str, keyword: str, lineno: int) -> float:
        words = arg.split()
        if not words:
            raise self.fail(lineno, f"{keyword} has no value")
        value = parse_number(words[0], False)
        if value is None or abs(value) > MAX_MAGNITUDE:
            raise self.fail(
                lineno,
                f"{keyword} is not a finite number of magnitude at most {MAX_MAGNITUDE:g} "
                f"({cut(words[0])})",
            )
        return value

    def declare_coord(self, arg: str, lineno: int) -> None:
        names = tuple(w.upper() for w in arg.split())
        for needed in ("X", "Y"):
            if needed not in names:
                raise self.fail(lineno, f".COORD has no {needed} (got {cut(arg.strip(), 60)})")
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise self.fail(lineno, f".COORD names {repeated[0]} twice")
        if self.coord is not None and names != self.coord and self.x:
            raise self.fail(lineno, ".COORD changes after pen data")
        self.coord = names
        self.columns = (
            names.index("X"),
            names.index("Y"),
            names.index("T") if "T" in names else None,
        )

    def segment(self, arg: str, lineno: int) -> Segment:
        label_match = _LABEL.search(arg)
        label = None
        head = arg
        if label_match:
            label = re.sub(
                r"\\(.)", lambda m: {"n": "\n", "t": "\t"}.get(m[1], m[1]), label_match[1]
            )
            head = arg[: label_match.start()]
        words = head.split()
        if not words:
            raise self.fail(lineno, ".SEGMENT has no type")
        spec = words[1] if len(words) > 1 and words[1] != "?" else None
        quality = words[2] if len(words) > 2 else None
        return Segment(words[0], spec, quality, label, lineno)

    # ----------------------------------------------------------------- samples

    def sample(self, raw: str, lineno: int) -> None:
        words = raw.split()
        if self.coord is not None:
            if len(words) != len(self.coord):
                raise self.fail(
                    lineno,
                    f"expected {len(self.coord)} numbers (.COORD {' '.join(self.coord)}), "
                    f"got {len(words)}",
                )
        elif len(words) < 2:
            raise self.fail(lineno, f"expected x and y, got {cut(raw.strip())}")
        values = []
        for word in words:
            try:  # float() alone would take "1_0", "nan" and non-ASCII digits
                v = float(word) if word.isascii() and "_" not in word else None
            except ValueError:
                v = None
            if v is None or not math.isfinite(v):
                raise self.fail(lineno, f"{cut(word)} is not a finite number")
            if abs(v) > MAX_MAGNITUDE:
                raise self.fail(
                    lineno, f"{cut(word)} is out of range (at most {MAX_MAGNITUDE:g} in magnitude)"
                )
            values.append(v)
        if len(self.x) >= MAX_POINTS:
            raise self.fail(lineno, f"more than {MAX_POINTS} samples")
        xi, yi, ti = self.columns
        self.x.append(values[xi])
        self.y.append(values[yi])
        if ti is not None:
            t = values[ti]
            if self.t_prev is not None and t < self.t_prev[0]:
                raise self.fail(
                    lineno,
                    f"T decreases ({cut(words[ti])} ms after {self.t_prev[0]!r} on line "
                    f"{self.t_prev[1]})",
                )
            self.t_prev = (t, lineno)
            self.t.append(t)
        self.lapse.append(self.dt)

    def close(self, pen: tuple[bool, int, int]) -> None:
        down, start, lineno = pen
        if len(self.x) > start:  # empty components are not counted
            self.components.append(_Component(down, start, len(self.x) - start, lineno))

    # ----------------------------------------------------------------- result

    def numberings(self) -> int:
        """How many separately numbered runs of components the file holds (sets with data)."""
        bounds = sorted(self.resets | {0, len(self.components)})
        return sum(1 for a, b in pairwise(bounds) if b > a)

    def finish(self) -> UnipenFile:
        per_x = self.per_mm.get("x") or self.per_mm.get("y")
        per_y = self.per_mm.get("y") or self.per_mm.get("x")
        xy = np.column_stack(
            [np.asarray(self.x, dtype=np.float64), np.asarray(self.y, dtype=np.float64)]
        )
        if per_x is not None and per_y is not None:
            xy = xy / np.array([per_x[0], per_y[0]])
        far = np.flatnonzero(~(np.abs(xy) <= MAX_MAGNITUDE).all(axis=1))
        if far.size:
            c = next(c for c in self.components if c.start + c.size > far[0])
            raise self.fail(c.line, f"a sample is beyond ±{MAX_MAGNITUDE:g} mm once converted")
        ticks = lapse = None
        rate = clock = None
        if self.columns[2] is not None:
            ticks = np.asarray(self.t)
            clock = "UNIPEN T column, milliseconds"
        elif self.rate is not None:
            rate = self.rate[0]
            ticks = np.arange(len(self.x), dtype=np.float64)
            lapse = np.asarray(self.lapse)
            clock = (
                f"UNIPEN .POINTS_PER_SECOND {rate:g}: sample index / rate, pen-up samples included"
            )
        return UnipenFile(
            self.name,
            xy,
            ticks,
            lapse,
            rate,
            tuple(self.components),
            self.numberings(),
            tuple(self.segments),
            tuple(self.includes),
            clock,
        )
