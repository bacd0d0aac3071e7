"""Trace: validated, read-only float64 copies."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.errors import InputError, TagbotError
from tagbot.inputs import Trace


def test_arrays_are_read_only_float_copies() -> None:
    xy = [[0, 0], [1, 2]]
    t = np.array([0.0, 0.5])
    tr = Trace(xy, t)
    assert tr.xy.dtype == np.float64 and tr.xy.shape == (2, 2)
    assert tr.t is not None and tr.t.dtype == np.float64
    assert not tr.xy.flags.writeable and not tr.t.flags.writeable
    t[0] = 99.0
    assert tr.t[0] == 0.0
    assert len(tr) == 2 and "2 points" in repr(tr)
    with pytest.raises(ValueError):
        tr.xy[0, 0] = 1.0


def test_single_point_and_untimed_are_fine() -> None:
    tr = Trace([[3.0, 4.0]])
    assert tr.t is None and len(tr) == 1 and "untimed" in repr(tr)


@pytest.mark.parametrize(
    ("xy", "t", "message"),
    [
        ([], None, "xy: expected shape (N, 2) with N >= 1"),
        ([[1.0, 2.0, 3.0]], None, "xy: expected shape (N, 2)"),
        ([[0.0, float("nan")]], None, "xy: point 0 is not finite"),
        ([["a", 1]], None, "xy: not an array of numbers"),
        ([[0, 0], [1, 1]], [0.0], "t: expected shape (2,) to match xy"),
        ([[0, 0], [1, 1]], [0.0, float("inf")], "t: point 1 is not finite"),
        ([[0, 0], [1, 1], [2, 2]], [0.0, 0.2, 0.1], "t: decreases at point 2 (0.1 after 0.2)"),
    ],
)
def test_invalid_values_name_the_field(xy, t, message) -> None:
    with pytest.raises(InputError) as e:
        Trace(xy, t)
    assert str(e.value).startswith(message)
    assert isinstance(e.value, ValueError) and isinstance(e.value, TagbotError)


def test_equal_times_are_allowed() -> None:
    assert Trace([[0, 0], [1, 1]], [0.5, 0.5]).t.tolist() == [0.5, 0.5]
