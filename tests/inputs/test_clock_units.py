"""GML clock units read from the point rate and span (milliseconds eyeSaver files and others)."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.inputs import read_gml
from tagbot.inputs.gml import SAMPLE_INTERVAL_MAX, SAMPLE_INTERVAL_MIN, SPAN_MAX

from .conftest import gml, stroke


def _read(*strokes_times: list[float], drawings: bool = False):
    strokes = [
        stroke(*[(0.1 + 0.01 * i, 0.5, repr(float(v))) for i, v in enumerate(ts)])
        for ts in strokes_times
    ]
    if drawings:  # EyeWriter: one <drawing> per stroke, the clock restarting in each
        body = "".join(f"<drawing>{s}</drawing>" for s in strokes)
        return read_gml(f"<GML><tag>{body}</tag></GML>".encode())
    return read_gml(gml(*strokes))


def _ticks(rate_hz_ticks: float, n: int, rng: np.random.Generator) -> list[float]:
    return np.cumsum(rng.uniform(0.8, 1.2, n) * rate_hz_ticks).round(6).tolist()


def test_eyesaver_milliseconds_restarting_per_drawing_become_seconds() -> None:
    """The temptTag pattern: <time> 0…406 in each drawing, about 20-50 ms apart."""
    first = [0.0, 56.781, 174.25, 222.453]
    second = [0.0, 46.25, 74.516, 110.469, 115.844, 131.344]
    traces = _read(first, second, drawings=True)
    assert traces[0].clock.startswith("milliseconds:")
    assert traces[0].clock == traces[1].clock
    assert np.allclose(traces[0].t, np.array(first) / 1e3)
    assert np.allclose(traces[1].t, (222.453 + np.array(second)) / 1e3)  # chained restart
    assert traces[-1].t[-1] < 1.0  # well under a second, not 6 minutes


@pytest.mark.parametrize(
    ("tick", "unit", "name"),
    [
        (0.016, 1.0, "seconds"),  # 62.5 Hz touch screen
        (0.005, 1.0, "seconds"),  # 200 Hz
        (16.0, 1e-3, "milliseconds"),
        (4.0, 1e-3, "milliseconds"),
        (10000.0, 1e-6, "microseconds"),
    ],
)
def test_unit_follows_the_median_sampling_interval(tick: float, unit: float, name: str) -> None:
    rng = np.random.default_rng(7)
    ts = _ticks(tick, 80, rng)
    traces = _read(ts[:50], ts[50:])
    assert traces[0].clock.startswith(f"{name}:")
    assert np.allclose(traces[1].t[-1], (ts[-1] - ts[0]) * unit)
    assert SAMPLE_INTERVAL_MIN <= np.median(np.diff(traces[0].t)) <= SAMPLE_INTERVAL_MAX


def test_duplicated_times_and_a_long_stall_do_not_change_the_unit() -> None:
    """Zero intervals do not count; a one-minute stall keeps a 60 Hz seconds file in seconds."""
    ts = [0.0, 0.016, 0.016, 0.032, 0.032, 0.048, 60.0, 60.016, 60.032]
    traces = _read(ts)
    assert traces[0].clock.startswith("seconds:")
    assert traces[0].t.tolist() == pytest.approx(ts)


def test_pen_lifts_do_not_count_as_sampling_intervals() -> None:
    """Each stroke 60 Hz in milliseconds, strokes a second apart: still milliseconds."""
    strokes = [[1000.0 * k + 16.0 * i for i in range(3)] for k in range(6)]
    traces = _read(*strokes)
    assert traces[0].clock.startswith("milliseconds:")
    assert traces[-1].t[-1] == pytest.approx(5.032)


def test_no_plausible_unit_keeps_seconds_and_says_so() -> None:
    traces = _read([0.0, 0.5, 1.0, 1.5])  # 2 Hz in seconds, or 2 kHz in milliseconds
    assert traces[0].clock.startswith("seconds (no unit gives a plausible rate")
    assert traces[0].t.tolist() == [0.0, 0.5, 1.0, 1.5]


def test_a_span_longer_than_plausible_is_not_a_plausible_unit() -> None:
    """A 60 ms median interval over more than an hour: said to be implausible, kept as seconds."""
    n = int(SPAN_MAX / 0.06) + 100
    ts = (np.arange(n) * 0.06).round(6).tolist()
    long = _read(ts)[0]
    assert long.clock.startswith("seconds (no unit gives a plausible rate")
    assert long.t[-1] == pytest.approx(ts[-1])
    assert _read(ts[: n // 2])[0].clock.startswith("seconds:")


def test_epoch_times_keep_the_unit_of_their_magnitude() -> None:
    traces = _read([1262304000000.0, 1262304000016.0, 1262304000033.0])
    assert traces[0].clock == "epoch milliseconds (by magnitude)"
    assert traces[0].t.tolist() == pytest.approx([0.0, 0.016, 0.033])


def test_untimed_traces_have_no_clock() -> None:
    traces = read_gml(gml(stroke((0.1, 0.2), (0.3, 0.4))))
    assert traces[0].t is None and traces[0].clock is None
