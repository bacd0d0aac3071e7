"""The DYNAMIXEL drawing arm: job time and fidelity per tag, loop timing over a pseudo-terminal.

Run from the repository root (``../shared/data`` adds a few fitted GML tags when present)::

    python benchmarks/bench_arm.py [--gml 4] [--data ../shared/data] [--rates 100,200,500]
                                   [--fidelity-rates 100] [--timing-tag letter-b.json]
                                   [--skip-timing] [--skip-fidelity]

Three parts, each printed as a table:

1. **Job time and fidelity per tag** (in process, simulated time): the shipped examples
   (``tagbot/examples``; captures fitted first) and, with ``--gml N`` and the shared data, N
   development GML tags evenly spaced in name order, fitted. Each is drawn twice through the
   back end (:func:`tagbot.arm.run.prepare`, then ``.run``) on the simulated chain: as before
   this change (``motion.time_scale=uniform``, ``motion.trim_ticks=0``,
   ``motion.max_deviation=0``: one time scale for the whole tag from the joint limits, every
   lognormal onset and tail drawn whole) and with the defaults (each pen-down run slowed only as
   much as its joint limits and the servos' predicted follow need, runs starting and ending where
   less than one tick at the pen is left). Reported per tag: the job's planned duration before →
   now (and the ratio; the uniform scale with trimmed runs alone in brackets), pen-down time,
   the share of pen-down time within one tick at the pen of where the lognormal motion starts
   and ends (the pen resting there; goal ≤ 2 %) and of the drawn run's own ends (the last tick
   of a lognormal tail is slow motion, not rest), and, from
   :func:`tagbot.metrics.compare_execution` on the simulator's 1 ms pen-tip recorder: the
   smallest per-run speed SNR and the overall one (goal ≥ 25 dB), the drawing-time ratio
   executed ÷ planned (goal 0.98–1.02) and the path deviation mean / max (goal ≤ 0.3 mm).
2. **Loop timing** (real time): ``tagbot sim arm`` runs in its own process (as a user would run
   it) and serves the default chain (1 Mbps bus) on a pty, clean or with every reply 16 ms late
   (an FTDI adapter's default latency timer) plus up to 2 ms of jitter and 2 % of replies lost
   (``--reply-latency 0.016 --reply-jitter 0.002 --drop 0.02``). The ``--timing-tag`` is drawn
   there through ``prepare(..., port=PATH).run`` at each rate, on an idle host and beside
   ``--hogs`` busy processes (a CPU load on the other core), with the loop's real-time
   scheduling (``SCHED_FIFO``, where permitted) and without it; reported from the run's report:
   the host's load average, whether the loop ran real-time, the period jitter p99 (|interval
   between goals leaving the host − period|), lateness p99 and max (goals leaving after their
   deadline), late ticks, resyncs, host stalls (count, total, longest), read-back replies late /
   missed, the path deviation max against ``motion.max_deviation`` and the speed SNR (from the
   100 Hz read-back: positions the servos reported), the warnings, and how the run ended.
3. **IK throughput**: :meth:`tagbot.arm.Arm.ik` on 10⁶ reachable points, points per second.
4. **OpenManipulator-X in the physics simulator** (``--serial-gml N``, ``--skip-serial``): the
   same tags through ``prepare(tag, profile="openmanipulator-x")`` and ``.run`` on the simulated
   chain with MuJoCo physics behind it (simulated time). Per tag: the path deviation max on the
   paper (goal ≤ 0.3 mm, the nib's contact points against the plan), the smallest per-run speed
   SNR (goal ≥ 25 dB), the smallest contact kept (goal 100 % of the planned ink length), the
   largest nib force, the job time against the joints' speed/acceleration bound (each move's own
   shape sped up until a joint meets a limit; goal ≤ 1.2×), the warnings, planning time (IK,
   retiming) and the simulation's speed against real time; the runs at 25 dB or more, and the
   arm's speed error (the median over all runs of each run's planned speed rms × 10^(−SNR/20))
   with the runs planned too slow (speed rms under 17.8× it) to show 25 dB over it, and for each
   run under 25 dB what its own plan scores, followed exactly (:func:`plan_ceilings`). Then
   ``--serial-timing-tag`` drawn in
   real time at 100 Hz over a ``tagbot sim arm --profile openmanipulator-x`` pty (its own
   process, physics running): loop rate, period jitter p99, lateness p99, late ticks, read-back
   replies missed, and how the run ended (``--skip-serial-timing`` leaves it out).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import tagbot
from tagbot.arm import Arm, build_program, load_profile
from tagbot.arm.place import time_at_ends
from tagbot.arm.run import prepare
from tagbot.draw import run_report
from tagbot.metrics import compare_execution
from tagbot.source import load_tag

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "tagbot" / "examples"
DATA = ROOT.parent / "shared" / "data"

BEFORE = ("motion.time_scale=uniform", "motion.trim_ticks=0", "motion.max_deviation=0")
"""Today's behaviour before per-run scales, trimmed runs and the tracking bound."""
UNIFORM = ("motion.time_scale=uniform",)
"""The uniform scale, runs trimmed."""

SNR_GOAL = 25.0  # dB, per run, at least
RATIO_GOAL = (0.98, 1.02)  # drawing time executed / planned
DEVIATION_GOAL = 0.3  # mm, path deviation max
SHARE_GOAL = 0.02  # pen-down time resting within one tick of the ends

FAULTS = {
    "clean": (),
    "16 ms late, 2 % lost": (
        "--reply-latency",
        "0.016",
        "--reply-jitter",
        "0.002",
        "--drop",
        "0.02",
    ),
}
"""Line conditions of the loop timing: ``tagbot sim arm`` options."""


def mark(ok: bool) -> str:
    return "✓" if ok else "✗"


# -- tags -----------------------------------------------------------------------------------------


def example_tags() -> list[tuple[str, Callable[[], tagbot.Tag]]]:
    """The shipped examples: plan files loaded, anything else fitted (``load_tag``)."""
    return [
        (path.name, lambda path=path: load_tag(str(path)))
        for path in sorted(EXAMPLES.glob("*.json"))
    ]


def gml_tags(data: Path, count: int) -> list[tuple[str, Callable[[], tagbot.Tag]]]:
    """``count`` development GML tags, evenly spaced in name order, fitted when loaded."""
    folder = data / "gml" / "dev"
    if count <= 0 or not folder.is_dir():
        return []
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.name != "index.csv")
    picks = sorted({round(i) for i in np.linspace(0, len(files) - 1, min(count, len(files)))})
    return [
        (f"gml/{files[i].name}", lambda path=files[i]: tagbot.fit(tagbot.load_traces(path)))
        for i in picks
    ]


# -- job time and fidelity ----------------------------------------------------------------------


def _draw(tag: tagbot.Tag, overrides: tuple[str, ...]) -> dict[str, Any]:
    """Draw ``tag`` on the in-process simulator through the back end; planned and measured."""
    job = prepare(tag, overrides=overrides)
    with tempfile.TemporaryDirectory() as out:
        run = job.run(Path(out))
    if run.error is not None:
        raise run.error
    comparison = compare_execution(
        run.planned_runs, run.executed, plans=run.plans, pauses=run.pauses, until=run.until
    )
    resting, down = time_at_ends(job.program, job.profile, tag)
    near, _ = time_at_ends(job.program, job.profile)
    return {
        "job": run.planned_duration,
        "down": down,
        "resting": resting / down,
        "near": near / down,
        "snr": comparison.speed_snr_db,
        "snr_min": min(r.snr_db for r in comparison.runs),
        "ratio": comparison.duration_ratio,
        "dev_mean": comparison.deviation_mean,
        "dev_max": comparison.deviation_max,
        "runs": f"{comparison.executed_runs}/{comparison.planned_runs}",
        "scales": job.program.setpoints.run_scales,
        "warnings": run.warnings + (run.judge(comparison.as_dict()) if run.judge else []),
    }


def fidelity(
    tags: list[tuple[str, Callable[[], tagbot.Tag]]], rates: list[int]
) -> list[dict[str, Any]]:
    """Each tag drawn as before and as now at each rate (simulated time)."""
    rows = []
    for name, load in tags:
        start = time.perf_counter()
        tag = load()
        for rate in rates:
            r = (f"motion.rate={rate}",)
            before, now = _draw(tag, BEFORE + r), _draw(tag, r)
            uniform = build_program(tag, load_profile(None, UNIFORM + r)).setpoints.duration
            rows.append(
                {
                    "tag": name,
                    "rate": rate,
                    "plans": len(tag.plans),
                    "before": before,
                    "now": now,
                    "uniform": uniform,
                    "wall": time.perf_counter() - start,
                }
            )
            start = time.perf_counter()
    return rows


def _fidelity_cells(m: dict[str, Any]) -> str:
    return (
        f" {m['snr_min']:.1f} / {m['snr']:.1f} | {m['ratio']:.3f} |"
        f" {m['dev_mean']:.3f} / {m['dev_max']:.3f} |"
    )


def print_fidelity(rows: list[dict[str, Any]]) -> None:
    print("Job time and fidelity per tag (in-process simulator, simulated time)")
    print(
        "| tag | Hz | plans | job s before → now (uniform, trimmed) | now ÷ before | pen-down s"
        " before → now | resting at the ends before → now | near the drawn ends"
        " | run scales now | mode | SNR min / all dB | drawing-time ratio | path dev mean / max"
        " mm | goals |"
    )
    print("|---|---:|---:|---|---:|---|---|---:|---|---|---|---:|---|---|")
    ratios = []
    for row in rows:
        b, n = row["before"], row["now"]
        ratios.append(n["job"] / b["job"])
        scales = ", ".join(f"{s:.2f}" for s in n["scales"])
        if len(n["scales"]) > 6:
            scales = f"{min(n['scales']):.2f} … {max(n['scales']):.2f}"
        ok = (
            n["resting"] <= SHARE_GOAL
            and n["snr_min"] >= SNR_GOAL
            and RATIO_GOAL[0] <= n["ratio"] <= RATIO_GOAL[1]
            and n["dev_max"] <= DEVIATION_GOAL
        )
        head = (
            f"| {row['tag']} | {row['rate']} | {row['plans']} | {b['job']:.2f} → {n['job']:.2f}"
            f" ({row['uniform']:.2f}) | {n['job'] / b['job']:.3f} | {b['down']:.2f} →"
            f" {n['down']:.2f} | {100 * b['resting']:.1f} % → {100 * n['resting']:.2f} % |"
            f" {100 * n['near']:.1f} % | {scales} |"
        )
        print(f"{head} before |{_fidelity_cells(b)} |")
        print(f"| | | | | | | | | | now |{_fidelity_cells(n)} {mark(ok)} |")
    for row in rows:
        for warning in row["now"]["warnings"]:
            print(f"  {row['tag']} at {row['rate']} Hz, now: {warning}")
    if ratios:
        print(
            f"\nJob time now ÷ before: median {np.median(ratios):.3f}, range"
            f" {min(ratios):.3f} to {max(ratios):.3f} over {len(ratios)} runs (tag, rate). Goals:"
            f" resting ≤ {100 * SHARE_GOAL:g} %, SNR min ≥ {SNR_GOAL:g} dB, drawing-time ratio"
            f" {RATIO_GOAL[0]} to {RATIO_GOAL[1]}, path deviation max ≤ {DEVIATION_GOAL} mm."
        )


# -- loop timing --------------------------------------------------------------------------------

STOP_WAIT = 10.0
"""s a simulator server is given to stop after each signal before the next, stronger one."""


def stop_server(server: subprocess.Popen) -> None:
    """Stop a ``tagbot sim`` server as Ctrl-C would (SIGINT), then, if it has not ended within
    :data:`STOP_WAIT` (started from a background job of a non-interactive shell it inherits
    SIGINT ignored), SIGTERM, then SIGKILL: no server outlives its benchmark."""
    for stop in (lambda: server.send_signal(signal.SIGINT), server.terminate, server.kill):
        if server.poll() is not None:
            return
        stop()
        try:
            server.wait(timeout=STOP_WAIT)
            return
        except subprocess.TimeoutExpired:
            continue


@contextlib.contextmanager
def hogs(count: int):
    """``count`` busy processes (``while True: pass``) for the duration."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]
    try:
        yield
    finally:
        for proc in procs:
            proc.kill()
            proc.wait(timeout=10)


@contextlib.contextmanager
def without_fifo(off: bool):
    """With ``off``, real-time scheduling refused as on a host that does not permit it."""
    if not off:
        yield
        return
    original = os.sched_setscheduler

    def refuse(*args: Any) -> None:
        raise PermissionError("benchmark: not permitted")

    os.sched_setscheduler = refuse  # type: ignore[assignment]
    try:
        yield
    finally:
        os.sched_setscheduler = original


def timing(
    rates: list[int], tag: tagbot.Tag, loads: list[int], fifo: list[bool]
) -> list[dict[str, Any]]:
    """Draw ``tag`` over a ``tagbot sim arm`` pty at each rate, clean and with late replies, on
    an idle host and beside busy processes, with and without real-time scheduling."""
    rows = []
    for load in loads:
        for fault, options in FAULTS.items():
            for rate in rates:
                for realtime in fifo:
                    rows.append(_timed(tag, rate, fault, options, load, realtime))
    return rows


def _timed(
    tag: tagbot.Tag, rate: int, fault: str, options: tuple[str, ...], load: int, realtime: bool
) -> dict[str, Any]:
    rate_option = f"motion.rate={rate}"
    server = subprocess.Popen(
        [sys.executable, "-m", "tagbot", "sim", "arm", "--set", rate_option, *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert server.stdout is not None
        path = server.stdout.readline().decode().strip()
        job = prepare(tag, overrides=(rate_option,), port=path)
        with hogs(load), without_fifo(not realtime), tempfile.TemporaryDirectory() as out:
            run = job.run(Path(out))
            loadavg = os.getloadavg()[0]
    finally:
        stop_server(server)
    report = run_report(run)
    d = run.details
    return {
        "fault": fault,
        "rate": rate,
        "load": load,
        "loadavg": loadavg,
        "ticks": d.get("ticks_sent", 0),
        "error": None if run.error is None else str(run.error),
        "budget": job.profile["motion.max_deviation"],
        **{key: report.get(key, math.nan) for key in _REPORT_KEYS},
        **{key: d.get(key, math.nan) for key in _TIMING_KEYS},
    }


_REPORT_KEYS = (
    "stalls",
    "stalled_s",
    "longest_stall_s",
    "path_deviation_max_mm",
    "speed_snr_db",
    "warnings",
)

_TIMING_KEYS = (
    "realtime",
    "loop_rate_hz",
    "period_jitter_p99_ms",
    "lateness_p99_ms",
    "max_lateness_ms",
    "late_ticks",
    "resyncs",
    "readback_requests",
    "readback_late_replies",
    "readback_missed_replies",
    "reply_delay_p99_ms",
)


def _number(value: Any, digits: int) -> str:
    return (
        "-"
        if value is None or (isinstance(value, float) and math.isnan(value))
        else (f"{value:.{digits}f}")
    )


def print_timing(rows: list[dict[str, Any]], tag: str) -> None:
    print(f"Loop timing over a pty (tagbot sim arm in its own process), drawing {tag}")
    print(
        "| line | busy procs (load avg) | FIFO | rate Hz | ticks | jitter p99 ms | lateness"
        " p99 / max ms | late ticks | resyncs | stalls (s, longest ms) | late / missed replies"
        " | dev max mm (budget) | SNR dB | warnings | result |"
    )
    print("|---|---|---|---:|---:|---:|---|---:|---:|---|---|---|---:|---:|---|")
    for row in rows:
        result = "completed" if row["error"] is None else f"stopped: {row['error']}"
        warnings = row["warnings"] if isinstance(row["warnings"], list) else []
        print(
            f"| {row['fault']} | {row['load']} ({row['loadavg']:.1f}) |"
            f" {'on' if row['realtime'] else 'off'} | {row['rate']} | {row['ticks']} |"
            f" {_number(row['period_jitter_p99_ms'], 3)} | {_number(row['lateness_p99_ms'], 2)}"
            f" / {_number(row['max_lateness_ms'], 1)} | {row['late_ticks']} | {row['resyncs']} |"
            f" {row['stalls']} ({_number(row['stalled_s'], 3)},"
            f" {_number(1e3 * row['longest_stall_s'], 0)}) |"
            f" {row['readback_late_replies']} / {row['readback_missed_replies']} |"
            f" {_number(row['path_deviation_max_mm'], 3)} ({row['budget']:g}) |"
            f" {_number(row['speed_snr_db'], 1)} | {len(warnings)} | {result} |"
        )
    for row in rows:
        for warning in row["warnings"] if isinstance(row["warnings"], list) else []:
            print(f"  {row['fault']}, {row['load']} busy, FIFO {row['realtime']}: {warning}")


# -- IK -----------------------------------------------------------------------------------------


def ik_throughput(points: int = 1_000_000) -> float:
    """Points per second through the vectorised closed-form IK (best of 5)."""
    arm = Arm.from_profile(load_profile())
    rng = np.random.default_rng(0)
    r = rng.uniform(10.0, 290.0, points)
    theta = rng.uniform(-math.pi, math.pi, points)
    xy = np.column_stack([r * np.cos(theta), r * np.sin(theta)])
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        arm.ik(xy)
        best = min(best, time.perf_counter() - start)
    return points / best


# -- the OpenManipulator-X in the physics simulator ---------------------------------------------

SERIAL = "openmanipulator-x"
TIME_GOAL = 1.2  # job time ÷ the joints' bound, at most


def serial_fidelity(tags: list[tuple[str, Callable[[], tagbot.Tag]]]) -> list[dict[str, Any]]:
    """Each tag drawn on the simulated OpenManipulator-X with physics; planned and measured."""
    rows = []
    for name, load in tags:
        tag = load()
        started = time.process_time()
        try:
            job = prepare(tag, profile=SERIAL)
        except tagbot.TagbotError as e:
            rows.append({"tag": name, "refused": str(e)})
            continue
        planning = time.process_time() - started
        wall = time.perf_counter()
        with tempfile.TemporaryDirectory() as out:
            run = job.run(Path(out))
        wall = time.perf_counter() - wall
        report = run_report(run)
        runs = report.get("runs", [])
        contacts = run.details["runs_contact"]
        ceilings = plan_ceilings(run.planned_runs)
        rows.append(
            {
                "tag": name,
                "runs": len(runs),
                "run_speeds": [
                    (
                        r["plan"],
                        path_length(run.planned_runs[i][1]),
                        speed_rms(*run.planned_runs[i]),
                        r["speed_snr_db"],
                        ceilings[i],
                    )
                    for i, r in enumerate(runs)
                ],
                "deviation": max((r["path_deviation_max_mm"] for r in runs), default=math.nan),
                "snr": min((r["speed_snr_db"] for r in runs), default=math.nan),
                "contact": min((c["contact_kept_pct"] for c in contacts), default=math.nan),
                "force": max((c["force_max_n"] for c in contacts), default=math.nan),
                "duration": report["planned_duration_s"],
                "bound": run.details["time_bound_s"],
                "scale": max(job.program.setpoints.run_scales),
                "planning": planning,
                "speedup": report["planned_duration_s"] / wall,
                "warnings": len(report["warnings"]),
                "error": report["error"],
            }
        )
    return rows


def path_length(xy: np.ndarray) -> float:
    """A planned run's length, mm."""
    return float(np.sum(np.hypot(*np.diff(np.asarray(xy, dtype=float), axis=0).T)))


def speed_rms(t: np.ndarray, xy: np.ndarray) -> float:
    """A planned run's speed rms over its samples (evenly spaced in time), mm/s."""
    t, xy = np.asarray(t, dtype=float), np.asarray(xy, dtype=float)
    if len(t) < 2:
        return 0.0
    return float(np.sqrt(np.mean(np.sum(np.gradient(xy, t, axis=0) ** 2, axis=1))))


REST = 0.05
"""s: how long :func:`plan_ceilings`' follower stands with its pen down before and after a run
(the arm's nib touches about this long before the ink starts and leaves after it ends)."""


def plan_ceilings(planned_runs: list[tuple[np.ndarray, np.ndarray]]) -> list[float]:
    """Per run, the speed SNR of a perfect machine: the planned positions exactly, at 1 ms,
    the pen down and at rest for :data:`REST` before and after each run, through
    :func:`~tagbot.metrics.compare_execution`. A trimmed run starts and ends moving, and the
    comparison's speeds (central differences on a 10 ms grid) cannot follow that step, so a
    short run's own plan scores only so much."""
    if not planned_runs:
        return []
    start = min(float(t[0]) for t, _ in planned_runs) - 2 * REST
    end = max(float(t[-1]) for t, _ in planned_runs) + 2 * REST
    t = np.arange(start, end, 0.001)
    xy, pen = np.zeros((len(t), 2)), np.zeros(len(t))
    for tp, xyp in planned_runs:
        tp, xyp = np.asarray(tp, dtype=float), np.asarray(xyp, dtype=float)
        held = (t >= tp[0] - REST) & (t <= tp[-1] + REST)
        pen[held] = 1.0
        for i in (0, 1):
            xy[held, i] = np.interp(t[held], tp, xyp[:, i])  # at rest at both ends
    comparison = compare_execution(planned_runs, np.column_stack([t, xy, pen]))
    return [float(r.snr_db) for r in comparison.runs]


def speed_error_floor(rows: list[dict[str, Any]]) -> float:
    """The arm's speed error, mm/s rms: over every run drawn, the median of its planned speed
    rms × 10^(−SNR/20) (the error rms that gives its SNR). It varies little from run to run
    (0.8-2 mm/s measured in session 21, whatever the run's speed): a run whose planned speed rms
    is under 10^(25/20) times it (17.8×) cannot show 25 dB over it."""
    errors = [
        v * 10.0 ** (-snr / 20.0)
        for r in rows
        for _, _, v, snr, _ in r.get("run_speeds", [])
        if snr is not None and math.isfinite(snr)
    ]
    return float(np.median(errors)) if errors else math.nan


def print_serial(rows: list[dict[str, Any]]) -> None:
    print("OpenManipulator-X, physics simulator (MuJoCo, 1 ms), 100 Hz, in process:")
    print(
        "| tag | runs | deviation max mm | SNR min dB | contact min % | force max N |"
        " job s | bound s | ratio | largest run scale | planning s | x real time | warnings |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "refused" in r:
            print(f"| {r['tag']} | refused: {r['refused']} |")
            continue
        ratio = r["duration"] / r["bound"]
        near = mark(r["deviation"] <= DEVIATION_GOAL)
        print(
            f"| {r['tag']} | {r['runs']} | {r['deviation']:.3f} {near}"
            f" | {r['snr']:.1f} {mark(r['snr'] >= SNR_GOAL)}"
            f" | {r['contact']:.1f} {mark(r['contact'] >= 100.0)} | {r['force']:.2f}"
            f" | {r['duration']:.2f} | {r['bound']:.2f} | {ratio:.2f} {mark(ratio <= TIME_GOAL)}"
            f" | {r['scale']:.2f} | {r['planning']:.2f} | {r['speedup']:.1f} | {r['warnings']} |"
        )
    floor = speed_error_floor(rows)
    needed = floor * 10.0 ** (SNR_GOAL / 20.0)
    speeds = [(r["tag"], *run) for r in rows for run in r.get("run_speeds", [])]
    slow = [run for run in speeds if run[3] < needed]
    passed = sum(1 for run in speeds if run[4] >= SNR_GOAL)
    print(
        f"Runs at {SNR_GOAL:g} dB or more: {passed} of {len(speeds)}. The arm's speed error, median"
        f" over the runs: {floor:.2f} mm/s rms; a run planned slower than {needed:.1f} mm/s rms"
        f" cannot show {SNR_GOAL:g} dB over it: {len(slow)} of {len(speeds)}. Under"
        f" {SNR_GOAL:g} dB, with what the plan itself scores followed exactly (its ends' step):"
    )
    for tag, plan, length, v, snr, ceiling in speeds:
        if snr < SNR_GOAL:
            print(
                f"  {tag} plan {plan}: {length:.1f} mm, {v:.1f} mm/s rms, {snr:.1f} dB;"
                f" exactly followed {ceiling:.1f} dB{'; too slow' if v < needed else ''}"
            )


def serial_timing(tag: tagbot.Tag) -> dict[str, Any]:
    """``tag`` drawn in real time over a ``tagbot sim arm --profile openmanipulator-x`` pty."""
    server = subprocess.Popen(
        [sys.executable, "-m", "tagbot", "sim", "arm", "--profile", SERIAL],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    try:
        assert server.stdout is not None
        path = server.stdout.readline().decode().strip()
        job = prepare(tag, profile=SERIAL, port=path)
        with tempfile.TemporaryDirectory() as out:
            run = job.run(Path(out))
            loadavg = os.getloadavg()[0]
    finally:
        stop_server(server)
    report = run_report(run)
    d = run.details
    return {
        "loadavg": loadavg,
        "ticks": d.get("ticks_sent", 0),
        "error": None if run.error is None else str(run.error),
        **{key: report.get(key, math.nan) for key in _REPORT_KEYS},
        **{key: d.get(key, math.nan) for key in _TIMING_KEYS},
    }


def print_serial_timing(row: dict[str, Any], tag: str) -> None:
    print(f"OpenManipulator-X over a pty with physics, real time, 100 Hz ({tag}):")
    print(
        f"load average {row['loadavg']:.2f}; loop rate {row['loop_rate_hz']:.2f} Hz; period"
        f" jitter p99 {row['period_jitter_p99_ms']:.2f} ms; lateness p99"
        f" {row['lateness_p99_ms']:.2f} ms, max {row['max_lateness_ms']:.2f} ms; late ticks"
        f" {row['late_ticks']} of {row['ticks']}; resyncs {row['resyncs']}; read-back replies"
        f" missed {row['readback_missed_replies']} of {4 * row['readback_requests']}, late"
        f" {row['readback_late_replies']}; host stalls {row['stalls']}; deviation max (read-back)"
        f" {_number(row['path_deviation_max_mm'], 3)} mm; speed SNR (read-back)"
        f" {_number(row['speed_snr_db'], 1)} dB; ended: {row['error'] or 'completed'}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gml", type=int, default=4, help="GML tags from ../shared/data")
    parser.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    parser.add_argument("--rates", default="100", help="loop rates of the timing, Hz")
    parser.add_argument("--hogs", default="0,1", help="busy processes beside the timing runs")
    parser.add_argument(
        "--fifo", default="on,off", help="real-time scheduling of the loop: on (if permitted), off"
    )
    parser.add_argument("--fidelity-rates", default="100", help="loop rates of part 1, Hz")
    parser.add_argument("--timing-tag", default="letter-b.json", help="example drawn over the pty")
    parser.add_argument("--skip-timing", action="store_true", help="no real-time pty part")
    parser.add_argument("--skip-fidelity", action="store_true", help="no per-tag part")
    parser.add_argument("--skip-ik", action="store_true", help="no IK throughput part")
    parser.add_argument("--serial-gml", type=int, default=4, help="GML tags for the OM-X part")
    parser.add_argument(
        "--serial-timing-tag", default="letter-b.json", help="example drawn over the OM-X pty"
    )
    parser.add_argument("--skip-serial", action="store_true", help="no OpenManipulator-X part")
    parser.add_argument(
        "--skip-serial-timing", action="store_true", help="no OpenManipulator-X pty timing"
    )
    args = parser.parse_args()
    rates = [int(r) for r in args.rates.split(",")]

    if not args.skip_fidelity:
        tags = example_tags() + gml_tags(args.data, args.gml)
        print_fidelity(fidelity(tags, [int(r) for r in args.fidelity_rates.split(",")]))
        print()
    if not args.skip_timing:
        tag = load_tag(str(EXAMPLES / args.timing_tag))
        loads = [int(n) for n in args.hogs.split(",")]
        fifo = [word == "on" for word in args.fifo.split(",")]
        print_timing(timing(rates, tag, loads, fifo), args.timing_tag)
        print()
    if not args.skip_ik:
        print(f"IK throughput: {ik_throughput() / 1e6:.1f} M points/s")
    if not args.skip_serial:
        print()
        tags = example_tags() + gml_tags(args.data, args.serial_gml)
        print_serial(serial_fidelity(tags))
        if not args.skip_serial_timing:
            print()
            tag = load_tag(str(EXAMPLES / args.serial_timing_tag))
            print_serial_timing(serial_timing(tag), args.serial_timing_tag)


if __name__ == "__main__":
    main()
