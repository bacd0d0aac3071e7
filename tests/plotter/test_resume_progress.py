"""A resumed plotter job's progress counts from the resume line, at the rate lines run."""

from __future__ import annotations

import io

from tqdm import tqdm

from tagbot.cli import bar_progress
from tagbot.plotter.machine import prepare

from .conftest import straight_tag


def test_a_resumed_job_reports_its_first_line_before_anything_runs(tmp_path, tiny_file):
    job = prepare(straight_tag(), profile=tiny_file)
    total = len(job.program.lines)
    resume = job.program.setpoint_lines[3] + 1  # 1-based: mid-stroke
    job = prepare(straight_tag(), profile=tiny_file, resume_from=resume)
    calls: list[tuple[int, int]] = []
    run = job.run(tmp_path, progress=lambda done, n: calls.append((done, n)))
    assert run.error is None
    assert calls[0] == (resume - 1, total)  # the skipped lines, before anything is sent
    assert all(done >= resume - 1 and n == total for done, n in calls)
    assert calls[-1][0] <= total


class _Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class _Bar(tqdm):  # type: ignore[type-arg]
    monitor_interval = 0  # no monitor thread


def test_the_bar_starts_at_the_resume_line_and_counts_the_lines_run():
    clock = _Clock()
    bar = _Bar(total=0, file=io.StringIO(), disable=False, mininterval=0, miniters=1)
    bar._time = clock
    progress = bar_progress(bar)
    progress(120, 300)  # resumed at line 121: 120 lines were done before
    for k in range(1, 11):
        clock.t = 0.1 * k
        progress(120 + k, 300)  # 10 lines a second
    meter = bar.format_dict
    assert meter["total"] == 300 and meter["n"] == 130 and meter["initial"] == 120
    rate = meter["rate"] or (meter["n"] - meter["initial"]) / meter["elapsed"]
    assert 9.0 < rate < 11.0
    bar.close()
