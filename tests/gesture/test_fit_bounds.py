"""The fit refuses, before any target is placed, a tag it would draw at the paper's rhythm for
longer than a tag may last (issue 29: bounded work): 10⁵ random points were refused only after
48 s of CPU and 3.7 GB. Work is checked by making the expensive steps fail, never by timing."""

from __future__ import annotations

import importlib
import os
from pathlib import Path

import numpy as np
import pytest

from tagbot.cli import main
from tagbot.errors import PlanError
from tagbot.gesture import reconstruction
from tagbot.inputs import Trace
from tagbot.model.plan import MAX_DURATION

reconstruct = importlib.import_module("tagbot.gesture.reconstruct")


def random_points(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.0, 1000.0, (n, 2))


@pytest.fixture
def no_fitting(monkeypatch):
    """The steps that cost (placing targets, refining) fail if they are reached."""

    def reached(*args, **kwargs):
        raise AssertionError("the fit's work began")

    monkeypatch.setattr(reconstruct, "correct_targets", reached)
    monkeypatch.setattr(reconstruct, "refine", reached)


SLOW = {"dt_min": 1800.0, "dt_max": 2200.0}
"""Delays of 1800-2200 s: 10 strokes or more outlast a tag's 4 h."""


@pytest.mark.parametrize(
    ("timing", "clock"),
    [("ignore", 0.01), ("auto", None), ("auto", 0.5), ("auto", 0.0001)],
    ids=["ignore", "untimed", "too-sparse-for-auto", "clock-too-fast"],
)
def test_a_tag_too_long_is_refused_before_any_work(no_fitting, timing, clock):
    """Drawn at the paper's rhythm (shape only, untimed, no usable clock, or a clock no hand
    produces: 20 strokes in 2 ms), the estimate already lasts more than 4 h: one error naming
    the points, the duration and the bound."""
    xy = random_points(20)
    trace = Trace(xy) if clock is None else Trace(xy, np.arange(20) * clock)
    with pytest.raises(PlanError) as e:
        reconstruction([trace], timing=timing, **SLOW)
    message = str(e.value)
    assert message.startswith("20 points: the tag would last at least ")
    assert f"more than {MAX_DURATION:g} s (a tag's longest); refused before fitting" in message
    least = float(message.split("at least ")[1].split(" s")[0])
    strokes = int(message.split("(")[1].split(" strokes")[0])
    size = float(np.hypot(*np.ptp(xy, axis=0)))
    part = reconstruct._analyse(xy, size, "gamma", reconstruct.FitOptions(**SLOW))
    assert strokes == len(part.dt) > 9
    # The estimate's delays, less the refinement's onset slack (half of 2200 - 1800 s).
    assert least == pytest.approx(float(part.dt.sum()) - 200.0, abs=0.5)


def test_a_clock_a_hand_can_produce_is_not_refused_early(monkeypatch):
    """Under ``match`` (or a plausible clock under ``auto``) the tag is drawn on the recorded
    clock, so the paper's rhythm says nothing about its length: the fit goes on."""
    reached = []
    real = reconstruct.correct_targets

    def counted(*args, **kwargs):
        reached.append(True)
        return real(*args, **kwargs)

    monkeypatch.setattr(reconstruct, "correct_targets", counted)
    theta = np.linspace(0.0, 2 * np.pi, 60)
    trace = Trace(np.column_stack([50 * np.cos(theta), 50 * np.sin(theta)]), np.arange(60) * 0.02)
    for timing in ("match", "auto"):
        reached.clear()
        fitted = reconstruction([trace], timing=timing, dt_min=1000.0, dt_max=1000.0)
        assert reached and fitted.timings is not None


def test_a_tag_within_the_bound_fits():
    """Estimated at 80 % of 4 h: fitted (not refused), and lasting at least the estimate (no
    splitting here: each split adds a stroke, and its delay, to the estimate's)."""
    xy = random_points(30, seed=2)
    size = float(np.hypot(*np.ptp(xy, axis=0)))
    strokes = len(reconstruct._analyse(xy, size, "gamma", reconstruct.FitOptions()).dt)
    delay = 0.8 * MAX_DURATION / (strokes - 1)
    slow = {"dt_min": delay, "dt_max": delay, "splits": 0}
    opts = reconstruct.FitOptions(**slow)
    least = reconstruct.shortest_duration([reconstruct._analyse(xy, size, "gamma", opts)], opts)
    assert least == pytest.approx(0.8 * MAX_DURATION, abs=1e-2)
    tag = reconstruction([xy], timing="ignore", **slow).tag
    assert least <= tag.end - tag.start <= MAX_DURATION


@pytest.mark.parametrize("seed", range(4))
def test_the_estimate_is_a_lower_bound_of_the_fitted_tag(seed):
    """Random points and several traces: the fitted tag (paper's rhythm) lasts no less than
    :func:`shortest_duration` of its estimates."""
    rng = np.random.default_rng(seed)
    polylines = [random_points(int(rng.integers(5, 200)), seed + k) for k in range(3)]
    size = float(np.hypot(*np.ptp(np.concatenate(polylines), axis=0)))
    opts = reconstruct.FitOptions()
    least = reconstruct.shortest_duration(
        [reconstruct._analyse(xy, size, "gamma", opts) for xy in polylines], opts
    )
    tag = reconstruction(polylines, timing="ignore").tag
    assert tag.end - tag.start >= least


def test_cli_names_the_file_and_exits_2(capsys, monkeypatch, tmp_path: Path, no_fitting):
    """``tagbot fit`` of random points stamped at 100 Hz (95 strokes per second: the paper's
    rhythm), the bound lowered to 60 s: one line naming the file, before any fitting."""
    monkeypatch.setattr(reconstruct, "MAX_DURATION", 60.0)
    xy = random_points(300)
    path = tmp_path / "random.csv"
    rows = ["x,y,t"] + [f"{x:.3f},{y:.3f},{0.01 * k:.2f}" for k, (x, y) in enumerate(xy)]
    path.write_text("\n".join(rows) + "\n")
    code = main(["fit", os.fspath(path)])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1, err
    assert err.startswith(f"tagbot: error: {path}: 300 points: the tag would last at least ")
    assert "more than 60 s (a tag's longest); refused before fitting" in err
