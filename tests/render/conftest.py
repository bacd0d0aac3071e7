"""Shared fixtures: example tags, a straight stroke, and a hand-made `tagbot draw` run folder."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tagbot.io.motionfile import write_motion_csv
from tagbot.io.planfile import load_plan, save_plan
from tagbot.model import DEFAULT_MU, DEFAULT_SIGMA, Plan, Tag

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "tagbot" / "examples"

MM_PER_UNIT = 0.5
TIME_SCALE = 2.0
DELAY = 0.3
"""Executed runs start this much (plus 0.1 s per run) after the planned ones."""


@dataclass(frozen=True)
class Table:
    """A motion as plain arrays (like a MotionTable)."""

    t: np.ndarray
    xy: np.ndarray
    v: np.ndarray
    speed: np.ndarray
    pen: np.ndarray


@pytest.fixture(scope="session")
def cae() -> Tag:
    return load_plan(EXAMPLES / "cae.json")


@pytest.fixture(scope="session")
def letter_b() -> Tag:
    return load_plan(EXAMPLES / "letter-b.json")


@pytest.fixture(scope="session")
def hello() -> Tag:
    """The demo's capture ("hello world", public domain, tagbot/examples/hello-world-147.json) as
    fitted once and kept here, so these tests do not follow changes of the fitter."""
    return load_plan(Path(__file__).with_name("hello-world-plan.json"))


@pytest.fixture(scope="session")
def line() -> Tag:
    """One straight stroke 100 units long along x: slow at both ends, fast in the middle."""
    plan = Plan([[0.0, 0.0], [100.0, 0.0]], [0.0], [DEFAULT_MU], [DEFAULT_SIGMA], [0.0], [0.0])
    return Tag((plan,))


def constant_speed_line(length: float = 100.0, speed: float = 50.0, dt: float = 0.002) -> Table:
    """A pen-down run along x at constant speed (every animation frame adds ink)."""
    t = np.arange(0.0, length / speed + dt / 2, dt)
    x = speed * t
    xy = np.column_stack([x, np.zeros_like(x)])
    v = np.column_stack([np.full_like(x, speed), np.zeros_like(x)])
    return Table(t, xy, v, np.full_like(x, speed), np.ones(len(t), dtype=np.int8))


def write_run_folder(folder: Path, tag: Tag, *, executed: bool = True) -> dict:
    """A run folder following `tagbot draw`'s contract: the tag placed at MM_PER_UNIT mm per unit
    and slowed TIME_SCALE times; the machine executes every run exactly, DELAY (+0.1 s per run)
    late on its own clock."""
    folder.mkdir(parents=True, exist_ok=True)
    save_plan(tag, folder / "plan.json")
    motion = tag.sample(0.005)
    offset = np.array([10.0, 20.0])
    t = (motion.t - tag.start) * TIME_SCALE
    planned = Table(
        t=t,
        xy=motion.xy * MM_PER_UNIT + offset,
        v=motion.v * MM_PER_UNIT / TIME_SCALE,
        speed=motion.speed * MM_PER_UNIT / TIME_SCALE,
        pen=motion.pen,
    )
    write_motion_csv(planned, folder / "motion.csv")
    runs = []
    rows = []
    for k, (p, run) in enumerate(motion.runs()):
        shift = DELAY + 0.1 * k
        start = float(t[run][0])
        runs.append({"plan": p, "planned_start": start, "executed_start": start + shift})
        for ti, (x, y) in zip(t[run].tolist(), planned.xy[run].tolist(), strict=True):
            rows.append(f"{ti + shift!r},{x!r},{y!r},1")
        rows.append(f"{float(t[run][-1]) + shift + 0.05!r},{float(planned.xy[run][-1][0])!r},0,0")
    if executed:
        (folder / "executed.csv").write_text("t,x,y,pen\n" + "\n".join(rows) + "\n")
    report = {
        "placement": {"mm_per_unit": MM_PER_UNIT, "time_scale": TIME_SCALE},
        "runs": runs,
    }
    (folder / "report.json").write_text(json.dumps(report))
    return report


@pytest.fixture
def run_dir(tmp_path: Path, cae: Tag) -> Path:
    folder = tmp_path / "run"
    write_run_folder(folder, cae)
    return folder
