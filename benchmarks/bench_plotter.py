"""The pen plotter: what its program asks of Grbl, and what the simulated Grbl did (issue 12).

Run from the repository root (``../shared/data`` adds a few fitted GML tags when present)::

    python benchmarks/bench_plotter.py [--gml 5] [--data ../shared/data] [--modes new,uniform,old]
                                       [--set KEY=VALUE] [--pause 0.5,2] [--csv plotter.csv]
                                       [--keep DIR] [--no-draw]

Every tag is drawn with the public API, exactly as ``tagbot draw TAG --device grbl`` does without
``--port``: :func:`tagbot.draw.draw` on the in-process simulated Grbl 1.1h (1 ms recorder of the
pen), once per *mode*, each a set of profile overrides so that today's and the new behaviour are
measured in one run:

- ``new``: the packaged defaults (per-run time scale, adaptive setpoints, trimmed run ends, lines
  never slower than Grbl steps);
- ``uniform``: the same with ``motion.time_scale=uniform`` (one scale for the whole tag);
- ``old``: the behaviour before issue 12: ``motion.time_scale=uniform``, ``motion.setpoints=fixed``
  (a line every ``motion.dt``), ``motion.trim=false``, ``motion.slow_lines=dwell`` (dwells before
  lines slower than Grbl's slowest step; now rounded to Grbl's 50 ms steps and counted), and
  ``motion.min_buffer=0``.

The tags: the shipped examples ``tagbot/examples/*.json`` (plan files as they are; other inputs
fitted by :func:`tagbot.source.load_tag`) and, with ``--gml N`` (default 5) and the shared data
present, N tags of ``gml/dev`` evenly spaced in name order, fitted with
``tagbot.fit(tagbot.load_traces(path))``.

Figures per tag and mode (the issue's goals in brackets), from the program (placed and built
again with the same profile: deterministic) and from the run's ``report.json``:

- job: planned and executed duration, s, and the executed job time against ``old``'s;
- rest: share of the planned pen-down motion time within one motor step of a run's first or
  last point (≤ 2 %);
- G4: dwells in the program, and those shorter than Grbl's 50 ms step (0); for ``old``, in
  brackets, how many sub-50 ms dwells the program before issue 12 wrote (now carried into the
  next line);
- min buffered: the least motion time, s, held by 15 consecutive setpoint lines of a run
  (``Program.min_buffered``), and by the 14 queued behind the executing one plus the 4 lines
  surely in the 128-byte receive buffer (``min_buffered_rx``: what a host pause may use; > 0.5);
- speed SNR executed vs planned, overall and the worst run, dB (≥ 25);
- drawing-time ratio executed / planned (0.98-1.02) and the job's;
- path deviation mean / max, mm (max ≤ 0.02);
- plan vs tag: the largest distance, mm, between the program's plan (straight lines in time
  between setpoints) and the exact retimed lognormal motion, and the worst run's speed SNR of
  the plan against the exact speed, dB: what the adaptive setpoints cost in fidelity;
- lines, the run time scales; planner starvation events (0);
- host pauses (``--pause 0.5,2``, default): the program streamed again into the simulated Grbl
  while the host stalls 0.5 s every 2 s of simulated time (the port's ``freeze_host`` hook:
  nothing sent or read meanwhile, as the 0.39-0.52 s stalls measured on a loaded host), with
  the planner's starvation events (0), how many came in a run's first moments (within what the
  receive buffer held behind the pen-down stop, ``Program.run_start_reserve``, whose least is
  shown: no timing lengthens it), and the executed job time.

The machine's pace, per tag and mode: the executed job time against the lower bound that the
speed, acceleration and junction limits alone allow (each run at the time scale those set for it
alone, the rest of the job as planned; ≤ 1.15), each run's limiting factor and scale
(``Run.limits``: ``buffer`` is ``motion.min_buffer``, ``segment`` Grbl's look-ahead over 15
blocks), the least motion the simulated Grbl actually held ahead of a drawing line (planner and
receive buffer, from its ``line_received_at`` / ``line_finished_at`` stamps; the planned
``min_buffered_rx`` in brackets), and each run's speed SNR and path deviation.

``--set`` adds a profile override to every mode but ``old`` (e.g. to sweep
``motion.tolerance``); ``--no-draw`` prints the program figures only (no simulation).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import tagbot
from tagbot.draw import draw
from tagbot.model.motion import evaluate_plan
from tagbot.plotter import build_program, load_profile, place
from tagbot.plotter.program import DWELL_STEP, resting_share
from tagbot.source import load_tag

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "tagbot" / "examples"
DATA = ROOT.parent / "shared" / "data"

MODES: dict[str, tuple[str, ...]] = {
    "new": (),
    "uniform": ("motion.time_scale=uniform",),
    "old": (
        "motion.time_scale=uniform",
        "motion.setpoints=fixed",
        "motion.trim=false",
        "motion.slow_lines=dwell",
        "motion.min_buffer=0",
    ),
}

REST_GOAL = 0.02
SNR_GOAL = 25.0
RATIO_GOAL = (0.98, 1.02)
DEVIATION_GOAL = 0.02
BUFFER_GOAL = 0.5


def mark(ok: bool) -> str:
    return "✓" if ok else "✗"


# -- tags -----------------------------------------------------------------------------------------


def example_tags() -> list[tuple[str, Callable[[], tagbot.Tag]]]:
    """The shipped examples: plan files loaded, anything else fitted (``load_tag``)."""

    def loader(path: Path) -> Callable[[], tagbot.Tag]:
        def load() -> tagbot.Tag:
            try:
                return tagbot.load_plan(path)
            except tagbot.PlanFileError:  # not a plan: an input to fit
                return load_tag(str(path))

        return load

    return [(path.name, loader(path)) for path in sorted(EXAMPLES.glob("*.json"))]


def gml_tags(data: Path, count: int) -> list[tuple[str, Callable[[], tagbot.Tag]]]:
    """``count`` development GML tags, evenly spaced in name order, fitted when loaded."""
    folder = data / "gml" / "dev"
    if count <= 0 or not folder.is_dir():
        return []
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.name != "index.csv")
    picks = sorted({round(i) for i in np.linspace(0, len(files) - 1, min(count, len(files)))})

    def loader(path: Path) -> Callable[[], tagbot.Tag]:
        return lambda: tagbot.fit(tagbot.load_traces(path))

    return [(f"gml/{files[i].name}", loader(files[i])) for i in picks]


# -- figures ------------------------------------------------------------------------------------


def plan_fidelity(tag: tagbot.Tag, setpoints: Any, program: Any) -> tuple[float, float]:
    """How closely the program's plan follows the tag: the largest distance, mm, between the
    planned position and the exact retimed motion (the tag's instants mapped to the job clock
    through the setpoints), and the worst run's speed SNR, dB, planned vs exact."""
    worst_dev, worst_snr = 0.0, math.inf
    for k, run in enumerate(setpoints.runs):
        lines = np.flatnonzero(program.line_run == k)
        if len(run.t) < 2 or not len(lines):
            continue
        job = np.concatenate([[program.line_start[lines[0]]], program.line_end[lines]])
        count = max(200, int((job[-1] - job[0]) / 0.002))
        instants = np.linspace(run.tag_t[0], run.tag_t[-1], count)
        p, v = evaluate_plan(tag.plans[run.plan], instants, tag.size)
        exact = p @ setpoints.matrix.T + setpoints.offset
        xy, velocity, _ = program.at(np.interp(instants, run.tag_t, job))
        worst_dev = max(worst_dev, float(np.max(np.hypot(*(exact - xy).T))))
        speed = np.hypot(*(v @ setpoints.matrix.T).T) / run.scale
        planned = np.hypot(*velocity.T)
        noise = float(np.sum((speed - planned) ** 2))
        if noise > 0:
            worst_snr = min(worst_snr, 10 * math.log10(float(np.sum(speed**2)) / noise))
    return worst_dev, worst_snr


MACHINE_LIMITS = ("speed", "acceleration", "junction")
"""The limits a job's lower bound keeps: the machine's, not the host's buffer rule."""


def lower_bound(setpoints: Any, program: Any, own: Any) -> tuple[float, list[str]]:
    """The job time the machine's speed, acceleration and junction limits alone allow: every
    run drawn at the time scale those set for it alone (``own``: the placement with
    ``motion.time_scale=run``; its drawing time in proportion), the rest of the job (travel
    trapezoids, pen changes, dwells, Grbl's $1 and reading after stops) as planned; and each
    run's limiting factor with its scale (``buffer x29.0``)."""
    fixed = program.duration - program.drawing_time
    drawing = 0.0
    limiting = []
    runs = zip(setpoints.runs, own.runs, program.planned_runs, strict=True)
    for run, alone, (t, _) in runs:
        limits = dict(run.limits) or {"speed": 1.0}
        machine = max([alone.limits.get(k, 1.0) for k in MACHINE_LIMITS] + [1.0])
        drawing += float(t[-1] - t[0]) * machine / float(run.scale)
        name = max(limits, key=lambda k: limits[k])
        limiting.append(f"{name} x{limits[name]:.1f}")
    return fixed + drawing, limiting


def achieved_buffer(device: Any, program: Any) -> float | None:
    """The least planned motion, s, the simulated Grbl held (planner and receive buffer) ahead
    of a drawing line as it began, over lines whose run was not yet all received; None when
    every run was held whole. From the device's stamps: each line's last byte's arrival and the
    instant each line had finished."""
    offset = device.lines_received - len(program.lines)
    received = np.asarray(device.line_received_at[offset:])
    finished = device.line_finished_at[offset:]
    least: float | None = None
    for k in range(1, len(program.lines)):
        run = program.line_run[k]
        if run < 0 or program.line_run[k - 1] != run or finished[k - 1] is None:
            continue
        j = int(np.searchsorted(received, finished[k - 1], side="right")) - 1
        if j + 1 >= len(program.lines) or program.line_run[j + 1] != run:
            continue  # the rest of the run is in the machine: held whole
        held = float(program.line_end[j] - program.line_start[k])
        least = held if least is None else min(least, held)
    return least


def program_figures(tag: tagbot.Tag, overrides: tuple[str, ...]) -> dict[str, Any]:
    """What the program asks of the machine (no simulation)."""
    profile = load_profile(None, overrides)
    start = time.perf_counter()
    setpoints = place(tag, profile)
    program = build_program(setpoints, profile)
    build_s = time.perf_counter() - start
    dwells = [float(line[3:]) for line in program.lines if line.startswith("G4P")]
    deviation, snr = plan_fidelity(tag, setpoints, program)
    own = place(tag, load_profile(None, (*overrides, "motion.time_scale=run")))
    bound, limiting = lower_bound(setpoints, program, own)
    return {
        "bound_s": bound,
        "limiting": limiting,
        "lines": len(program.lines),
        "planned_s": program.duration,
        "drawing_s": program.drawing_time,
        "scale_max": max(program.run_scales, default=1.0),
        "scale_min": min(program.run_scales, default=1.0),
        "runs": len(program.run_scales),
        "rest": resting_share(program, profile),
        "dwells": len(dwells),
        "short_dwells": sum(p < DWELL_STEP - 1e-9 for p in dwells),
        "short_before": int(program.notes.get("short_surpluses", 0)),
        "min_buffered_s": program.min_buffered,
        "min_buffered_rx_s": program.min_buffered_rx,
        "plan_dev_mm": deviation,
        "plan_snr_db": snr,
        "build_s": build_s,
    }


def draw_figures(tag: tagbot.Tag, overrides: tuple[str, ...], out: Path) -> dict[str, Any]:
    """Draw on the simulated Grbl; the report's figures."""
    start = time.perf_counter()
    draw(tag, out, device="grbl", pictures=False, overrides=overrides)
    wall = time.perf_counter() - start
    r = json.loads((out / "report.json").read_text(encoding="utf-8"))
    runs = r.get("runs") or []
    snrs = [run["speed_snr_db"] for run in runs if run.get("speed_snr_db") is not None]
    details = r.get("details", {})
    executed = r["executed_duration_s"]
    return {
        "executed_s": executed,
        "job_ratio": executed / r["planned_duration_s"] if r["planned_duration_s"] else math.nan,
        "drawing_ratio": r["drawing_duration_ratio"],
        "snr_db": r["speed_snr_db"],
        "run_snr_min_db": min(snrs) if snrs else math.nan,
        "dev_mean_mm": r["path_deviation_mean_mm"],
        "dev_max_mm": r["path_deviation_max_mm"],
        "run_snr_db": [run.get("speed_snr_db") for run in runs],
        "run_dev_mm": [run.get("path_deviation_max_mm") for run in runs],
        "starvation": details.get("starvation_events"),
        "wall_s": wall,
    }


def pause_figures(
    tag: tagbot.Tag, overrides: tuple[str, ...], pause: float, every: float, name: str
) -> dict[str, Any]:
    """Stream the program into the simulated Grbl while the host stalls ``pause`` s every
    ``every`` s (the port's ``freeze_host`` hook: nothing sent or read meanwhile); the planner's
    starvation events and the executed job time."""
    device, executed = stream_program(tag, overrides, name, pause, every)
    profile = load_profile(None, overrides)
    program = build_program(place(tag, profile), profile)
    at_start = sum(starved_at_start(device, program, t, pause) for t in device.starvation)
    return {
        "pause_starvation": len(device.starvation),
        "pause_starvation_start": at_start,
        "pause_executed_s": executed,
        "start_reserve_s": program.min_buffered_start,
    }


def starved_at_start(device: Any, program: Any, at: float, pause: float) -> bool:
    """Whether the planner ran dry at ``at`` (the simulated Grbl's clock) in a run's first
    moments: within what the run's start held (``Program.run_start_reserve``, where the pen-down
    stop had left only the receive buffer's lines queued) and a host pause of ``pause`` s begun
    there, of the run's start."""
    finished = np.array([np.nan if f is None else f for f in device.line_finished_at])
    line = min(int(np.searchsorted(finished, at)), len(program.lines) - 1)
    run = int(program.line_run[line])
    if run < 0:
        return False
    first = int(np.flatnonzero(program.line_run == run)[0])
    into = program.line_start[line] - program.line_start[first]
    return bool(into <= program.run_start_reserve[run] + pause)


def buffer_figures(tag: tagbot.Tag, overrides: tuple[str, ...], name: str) -> dict[str, Any]:
    """Stream the program into the simulated Grbl (no host stall): the least motion it held
    ahead of a drawing line (:func:`achieved_buffer`)."""
    device, _ = stream_program(tag, overrides, name)
    profile = load_profile(None, overrides)
    program = build_program(place(tag, profile), profile)
    return {"achieved_buffer_s": achieved_buffer(device, program)}


def stream_program(
    tag: tagbot.Tag,
    overrides: tuple[str, ...],
    name: str,
    pause: float = 0.0,
    every: float = math.inf,
) -> tuple[Any, float]:
    """The program streamed into a simulated Grbl, the host stalling ``pause`` s every
    ``every`` s: the device and the executed job time."""
    import serial

    from sim.grbl import SimulatedGrbl
    from sim.grbl.transport import attach_device
    from tagbot.plotter.machine import simulated_pen
    from tagbot.plotter.profile import device_settings
    from tagbot.plotter.program import pen_up
    from tagbot.plotter.stream import GrblStreamer, StreamOptions

    profile = load_profile(None, overrides)
    program = build_program(place(tag, profile), profile)
    device = SimulatedGrbl(device_settings(profile), **simulated_pen(profile))
    url = attach_device(device, re.sub(r"\W", "_", f"bench_{name}_{pause:g}"))
    link = serial.serial_for_url(url, baudrate=profile["serial.baud"], timeout=0.01)
    try:
        streamer = GrblStreamer(link, StreamOptions())
        streamer.connect()
        start = link.clock.now()
        for k in range(1, int(program.duration / every) + 1 if pause > 0 else 1):
            link.freeze_host(start + k * every, pause)
        streamer.stream(
            list(program.lines),
            pen_up=pen_up(profile),
            moves=program.line_moves,
            targets=program.line_xy,
        )
        executed = streamer.last_report.duration
    finally:
        link.close()
    return device, executed


def measure(
    name: str,
    tag: tagbot.Tag,
    modes: list[str],
    simulate: bool,
    keep: Path | None,
    pause: tuple[float, float] | None = None,
) -> list[dict[str, Any]]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_plotter_") as scratch:
        slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
        for mode in modes:
            row: dict[str, Any] = {"tag": name, "mode": mode}
            row.update(program_figures(tag, MODES[mode]))
            if simulate:
                out = (keep if keep is not None else Path(scratch)) / f"{slug}_{mode}"
                row.update(draw_figures(tag, MODES[mode], out))
                row.update(buffer_figures(tag, MODES[mode], f"{slug}_{mode}"))
                if pause is not None:
                    row.update(pause_figures(tag, MODES[mode], *pause, f"{slug}_{mode}"))
            rows.append(row)
    old = next((r for r in rows if r["mode"] == "old"), None)
    for row in rows:
        key = "executed_s" if "executed_s" in row else "planned_s"
        row["vs_old"] = row[key] / old[key] if old else math.nan
    return rows


# -- printing -------------------------------------------------------------------------------------


def print_program(rows: list[dict[str, Any]]) -> None:
    print(
        "| tag | mode | lines | runs | run scale min-max | planned job s (vs old) | drawing s"
        " | rest (≤ 2 %) | G4 / < 50 ms (0) | min buffered 15 lines s | + RX s (> 0.5) |"
        " plan vs tag: max mm / worst run SNR dB | build s |"
    )
    print("|---|---|---:|---:|---|---:|---:|---:|---|---:|---:|---|---:|")
    for r in rows:
        print(
            f"| {r['tag']} | {r['mode']} | {r['lines']:,} | {r['runs']} |"
            f" {r['scale_min']:.1f}-{r['scale_max']:.1f} |"
            f" {r['planned_s']:.1f} ({r['planned_s'] / r['old_planned_s']:.2f}) |"
            f" {r['drawing_s']:.1f} | {100 * r['rest']:.1f} % {mark(r['rest'] <= REST_GOAL)} |"
            f" {r['dwells']} / {r['short_dwells']} {mark(r['short_dwells'] == 0)}"
            + (f" (before: {r['short_before']})" if r["mode"] == "old" else "")
            + " |"
            f" {r['min_buffered_s']:.3f} | {r['min_buffered_rx_s']:.3f}"
            f" {mark(r['min_buffered_rx_s'] > BUFFER_GOAL)} |"
            f" {r['plan_dev_mm']:.4f} / {r['plan_snr_db']:.1f} | {r['build_s']:.2f} |"
        )


def print_draw(rows: list[dict[str, Any]]) -> None:
    print(
        "| tag | mode | executed job s (vs old) | job ratio | drawing ratio (0.98-1.02) |"
        " speed SNR dB / worst run (≥ 25) | deviation mean / max mm (≤ 0.02) | starvation |"
        " with host pauses: starvation (0) / job s | wall s |"
    )
    print("|---|---|---:|---:|---:|---|---|---:|---|---:|")
    for r in rows:
        ratio_ok = RATIO_GOAL[0] <= r["drawing_ratio"] <= RATIO_GOAL[1]
        print(
            f"| {r['tag']} | {r['mode']} | {r['executed_s']:.1f} ({r['vs_old']:.2f}) |"
            f" {r['job_ratio']:.3f} | {r['drawing_ratio']:.3f} {mark(ratio_ok)} |"
            f" {r['snr_db']:.1f} / {r['run_snr_min_db']:.1f}"
            f" {mark(r['run_snr_min_db'] >= SNR_GOAL)} |"
            f" {r['dev_mean_mm']:.4f} / {r['dev_max_mm']:.4f}"
            f" {mark(r['dev_max_mm'] <= DEVIATION_GOAL)} | {r['starvation']} |"
            + (
                f" {r['pause_starvation']} {mark(r['pause_starvation'] == 0)}"
                f" ({r['pause_starvation_start']} at a run's start; least start reserve"
                f" {r['start_reserve_s']:.2f} s) / {r['pause_executed_s']:.1f} |"
                if "pause_starvation" in r
                else " - |"
            )
            + f" {r['wall_s']:.1f} |"
        )


def print_pace(rows: list[dict[str, Any]]) -> None:
    """Per tag: the job against the machine's lower bound, each run's limiting factor, the
    buffered motion achieved, per-run speed SNR and deviation."""
    print(
        "| tag | mode | executed job s / lower bound s (≤ 1.15) | limiting factor per run |"
        " min buffered achieved s (planned) | per-run speed SNR dB (≥ 25) |"
        " per-run deviation max mm (≤ 0.05) |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = r["executed_s"] / r["bound_s"]
        achieved = r.get("achieved_buffer_s")
        planned = r["min_buffered_rx_s"]
        snrs = [x for x in r["run_snr_db"] if x is not None]
        devs = [x for x in r["run_dev_mm"] if x is not None and math.isfinite(x)]
        print(
            f"| {r['tag']} | {r['mode']} | {r['executed_s']:.1f} / {r['bound_s']:.1f} ="
            f" {ratio:.2f} {mark(ratio <= 1.15)} | {', '.join(r['limiting'])} |"
            f" {'held whole' if achieved is None else f'{achieved:.3f}'}"
            f" ({'-' if math.isinf(planned) else f'{planned:.3f}'}) |"
            f" {' '.join(f'{x:.1f}' for x in snrs)} {mark(min(snrs, default=0) >= SNR_GOAL)} |"
            f" {' '.join(f'{x:.3f}' for x in devs)} {mark(max(devs, default=0) <= 0.05)} |"
        )


def print_totals(rows: list[dict[str, Any]], simulate: bool) -> None:
    key = "executed_s" if simulate else "planned_s"
    print()
    for mode in dict.fromkeys(r["mode"] for r in rows):
        mine = [r for r in rows if r["mode"] == mode]
        total = sum(r[key] for r in mine)
        old = sum(r[key] for r in rows if r["mode"] == "old")
        versus = f" ({total / old:.2f} of old)" if old else ""
        print(
            f"- {mode}: {len(mine)} tags, {total:.0f} s of {key[:-2]} job time{versus};"
            f" rest ≤ 2 % on {sum(r['rest'] <= REST_GOAL for r in mine)}, no short dwell on"
            f" {sum(r['short_dwells'] == 0 for r in mine)}, buffer > 0.5 s on"
            f" {sum(r['min_buffered_rx_s'] > BUFFER_GOAL for r in mine)}"
            + (
                f", run SNR ≥ 25 dB on {sum(r['run_snr_min_db'] >= SNR_GOAL for r in mine)},"
                f" deviation ≤ 0.02 mm on {sum(r['dev_max_mm'] <= DEVIATION_GOAL for r in mine)},"
                " drawing ratio in 0.98-1.02 on"
                f" {sum(RATIO_GOAL[0] <= r['drawing_ratio'] <= RATIO_GOAL[1] for r in mine)}"
                if simulate
                else ""
            )
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gml", type=int, default=5, help="GML tags from ../shared/data")
    parser.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    parser.add_argument("--modes", default="new,uniform,old", help="modes to compare")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a profile override for every mode but old (repeatable)",
    )
    parser.add_argument(
        "--pause",
        default="0.5,2",
        help="host stalls SECONDS,EVERY (simulated; empty: none), e.g. 0.5,2",
    )
    parser.add_argument("--no-draw", action="store_true", help="program figures only")
    parser.add_argument("--csv", type=Path, help="write every row to this CSV file")
    parser.add_argument("--keep", type=Path, help="keep the run folders under this directory")
    args = parser.parse_args()
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    unknown = [m for m in modes if m not in MODES]
    if unknown:
        raise SystemExit(f"--modes: unknown {', '.join(unknown)} (known: {', '.join(MODES)})")
    if "old" not in modes:
        modes.append("old")
    simulate = not args.no_draw
    pause = tuple(float(v) for v in args.pause.split(",")) if args.pause else None
    if pause is not None and len(pause) != 2:
        raise SystemExit("--pause: expected SECONDS,EVERY, e.g. 0.5,2")
    for mode in modes:
        if mode != "old":
            MODES[mode] = (*MODES[mode], *args.set)

    rows: list[dict[str, Any]] = []
    failures: list[str] = []
    for name, load in example_tags() + gml_tags(args.data, args.gml):
        try:
            rows += measure(name, load(), modes, simulate, args.keep, pause)
        except Exception as e:  # a failure is a figure, never dropped
            failures.append(f"{name}: {type(e).__name__}: {e}")
    old_planned = {r["tag"]: r["planned_s"] for r in rows if r["mode"] == "old"}
    for r in rows:
        r["old_planned_s"] = old_planned[r["tag"]]

    print("Programs (default A3 servo-pen profile; ✓ goal met, ✗ missed)")
    print_program(rows)
    if simulate:
        print("\nOn the simulated Grbl 1.1h, 115200 baud")
        print_draw(rows)
        print("\nThe machine's pace (lower bound: speed, acceleration and junction limits alone)")
        print_pace(rows)
    print_totals(rows, simulate)
    for failure in failures:
        print(f"FAILED {failure}")
    if args.csv and rows:
        with open(args.csv, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
