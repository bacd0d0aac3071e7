"""The :class:`Trace`: one pen-down polyline read from an input file."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tagbot.errors import InputError

__all__ = ["Trace"]


@dataclass(frozen=True, eq=False)
class Trace:
    """One pen-down polyline, y up, with optional timestamps.

    Both arrays are float64 copies made read-only on construction. Invalid values raise
    :class:`~tagbot.errors.InputError` naming the field, e.g. ``t: decreases at point 3``.
    """

    xy: np.ndarray
    """Pen positions, shape (N, 2), N >= 1, finite; y points up. Readers return millimetres."""
    t: np.ndarray | None = None
    """Times in seconds, shape (N,), finite and non-decreasing, or None when the source has no
    usable timing. All traces read from one file share its clock: the file's first point is at 0,
    so the gaps between traces (pen lifts) are kept."""
    clock: str | None = None
    """How the source's clock was read as seconds, when a reader had to decide it (e.g.
    ``"milliseconds: median interval 24 → 24 ms (42 Hz), span 2828 → 2.83 s"``); None when the
    trace is untimed or its unit is fixed by the format. Fit reports repeat it."""

    def __post_init__(self) -> None:
        try:
            xy = np.array(self.xy, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"xy: not an array of numbers ({e})") from e
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 1:
            raise InputError(f"xy: expected shape (N, 2) with N >= 1, got {xy.shape}")
        bad = np.flatnonzero(~np.isfinite(xy).all(axis=1))
        if bad.size:
            raise InputError(f"xy: point {bad[0]} is not finite: {xy[bad[0]].tolist()}")
        xy.flags.writeable = False
        object.__setattr__(self, "xy", xy)
        if self.clock is not None and not isinstance(self.clock, str):
            raise InputError(f"clock: expected a string or None, got {type(self.clock).__name__}")
        if self.t is None:
            return
        try:
            t = np.array(self.t, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"t: not an array of numbers ({e})") from e
        if t.shape != (xy.shape[0],):
            raise InputError(f"t: expected shape ({xy.shape[0]},) to match xy, got {t.shape}")
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size:
            raise InputError(f"t: point {bad[0]} is not finite: {float(t[bad[0]])!r}")
        dec = np.flatnonzero(np.diff(t) < 0)
        if dec.size:
            i = int(dec[0]) + 1
            raise InputError(
                f"t: decreases at point {i} ({float(t[i])!r} after {float(t[i - 1])!r})"
            )
        t.flags.writeable = False
        object.__setattr__(self, "t", t)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def __repr__(self) -> str:
        timing = "untimed" if self.t is None else f"{self.t[0]:.3f}..{self.t[-1]:.3f} s"
        return f"Trace({len(self)} points, {timing})"
