"""The pen plotter end to end: development tags through the simulated Grbl at 115200 baud (issue 4).

Run from the repository root (``../shared/data`` adds a few fitted GML tags when present)::

    python benchmarks/bench_plotter.py [--dt 0.01] [--gml 5] [--data ../shared/data]
                                       [--sweep-dt 0.002,0.005,0.01,0.02] [--sweep-tag NAME]
                                       [--csv plotter.csv] [--keep DIR]

Every development tag is drawn with the public API, exactly as ``tagbot draw TAG --device grbl``
does without ``--port``: :func:`tagbot.draw.draw` with the default profile (an A3 servo-pen
plotter, 115200 baud, one inverse-time G-code line per setpoint) on the in-process simulated
Grbl 1.1h (128-byte receive buffer, 15-block look-ahead planner, stepper segments, 1 ms recorder
of the pen), streamed with character counting. The tags:

- the shipped examples ``tagbot/examples/*.json`` (plan files as they are; other inputs, such as
  the DustTag capture, fitted first by :func:`tagbot.source.load_tag`);
- with ``--gml N`` (default 5) and the shared data present, N tags of ``gml/dev`` evenly spaced
  in name order, fitted with ``tagbot.fit(tagbot.load_traces(path))``.

From each run's ``report.json`` (the issue's goals in brackets):

- lines of G-code, the uniform time scale of the retiming and the limit that set it (from
  ``placement.limits``; every limit within 1 % of the scale is named);
- speed SNR executed vs planned, dB (≥ 20);
- pen-down path deviation mean / max, mm (max ≤ 0.1);
- drawing duration executed / planned, pen-down runs from first to last movement (≤ 1.05),
  and the whole job's executed duration over the program's estimate (travel, pen dwells);
- planner starvation events (0): the planner ran dry though no line asked for a stop;
- streaming: bytes sent over the executed duration (status polls included), against the link's
  capacity (115200 baud, 8N1: 11,520 bytes/s); and what the job *needs*: the bytes of the
  pen-down G-code (between ``G93`` and ``G94``) per second of their planned time, overall and
  over the busiest second;
- wall time of the whole ``draw`` call (placement, program, simulation, comparison) and the
  speed-up of the simulation over real time (executed duration ÷ wall time).

``--sweep-dt`` repeats the figures for one tag (``--sweep-tag``, default the DustTag capture) at
other time steps, to show where the 115200-baud link or Grbl's planner becomes the limit.
"""

from __future__ import annotations

import argparse
import csv
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
from tagbot.source import load_tag

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "tagbot" / "examples"
DATA = ROOT.parent / "shared" / "data"

SNR_GOAL = 20.0  # dB, at least
DEVIATION_GOAL = 0.1  # mm, path deviation max at most
RATIO_GOAL = 1.05  # executed / planned duration, at most
STARVATION_GOAL = 0

_FEED = re.compile(r"F([0-9.]+)")


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


def drawing_demand(program: Path) -> tuple[float, float, float, int]:
    """What the pen-down G-code asks of the link: ``(bytes/s overall, bytes/s in the busiest
    second, planned drawing seconds, drawing bytes)``.

    Pen-down lines are those between ``G93`` and ``G94``; each lasts ``60/F`` s (inverse time) or
    its ``G4 P`` dwell; a line's bytes count its newline.
    """
    sections: list[list[tuple[float, int]]] = []
    current: list[tuple[float, int]] | None = None
    for line in program.read_text(encoding="ascii").splitlines():
        if line == "G93":
            current = []
            sections.append(current)
        elif line == "G94":
            current = None
        elif current is not None:
            if line.startswith("G4P"):
                seconds = float(line[3:])
            else:
                feed = _FEED.search(line)
                seconds = 60.0 / float(feed.group(1)) if feed else 0.0
            current.append((seconds, len(line) + 1))
    total_s = sum(s for sec in sections for s, _ in sec)
    total_b = sum(b for sec in sections for _, b in sec)
    peak = 0.0
    for sec in sections:
        if not sec:
            continue
        t = np.cumsum([s for s, _ in sec])
        b = np.cumsum([n for _, n in sec])
        if t[-1] <= 1.0:
            peak = max(peak, b[-1] / max(t[-1], 1e-9))
            continue
        # bytes whose lines end within (t_i - 1 s, t_i]
        start = np.searchsorted(t, t - 1.0, side="right")
        before = np.where(start > 0, b[np.maximum(start - 1, 0)], 0)
        peak = max(peak, float(np.max(b - before)))
    return total_b / total_s if total_s else math.nan, peak, total_s, total_b


def run_tag(name: str, tag: tagbot.Tag, dt: float, keep: Path | None) -> dict[str, Any]:
    """Draw ``tag`` on the simulated Grbl at step ``dt``; the figures of one row."""
    with tempfile.TemporaryDirectory(prefix="bench_plotter_") as scratch:
        slug = re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
        out = (keep if keep is not None else Path(scratch)) / f"{slug}_dt{dt:g}"
        start = time.perf_counter()
        result = draw(tag, out, device="grbl", pictures=False, overrides=(f"motion.dt={dt}",))
        wall = time.perf_counter() - start
        need, need_peak, drawing_s, drawing_bytes = drawing_demand(out / "program.gcode")
    r = result.report
    limits = r["placement"]["limits"]
    capacity = r["baud_limit_bytes_per_s"]
    scale = max(limits.values())
    return {
        "tag": name,
        "dt": dt,
        "lines": r["lines_total"],
        "acked": r["lines_acknowledged"],
        "errors": len(r["errors"]),
        "time_scale": r["time_scale"],
        # which limit set the scale: every one within 1 % of it (the speed limit and the
        # short-segment cap are often within a rounding of each other)
        "limit": "/".join(
            k for k in sorted(limits, key=limits.get, reverse=True) if limits[k] >= 0.99 * scale
        ),
        "mm_per_unit": r["placement"]["mm_per_unit"],
        "snr_db": r["speed_snr_db"],
        "run_snr_min_db": min(run["speed_snr_db"] for run in r["runs"]),
        "dev_mean_mm": r["path_deviation_mean_mm"],
        "dev_max_mm": r["path_deviation_max_mm"],
        "drawing_ratio": r["drawing_duration_ratio"],
        "job_ratio": r["duration_ratio"],
        "executed_s": r["executed_duration_s"],
        "starvation": r["starvation_events"],
        "max_outstanding": r["max_outstanding_bytes"],
        "bytes_sent": r["bytes_sent"],
        "rate": r["stream_rate_bytes_per_s"],
        "capacity": capacity,
        "need": need,
        "need_peak": need_peak,
        "drawing_bytes": drawing_bytes,
        "drawing_s": drawing_s,
        "wall_s": wall,
        "speedup": r["executed_duration_s"] / wall,
    }


def goals(row: dict[str, Any]) -> dict[str, bool]:
    return {
        "snr": row["snr_db"] >= SNR_GOAL,
        "dev": row["dev_max_mm"] <= DEVIATION_GOAL,
        "drawing": row["drawing_ratio"] <= RATIO_GOAL,
        "job": row["job_ratio"] <= RATIO_GOAL,
        "starvation": row["starvation"] == STARVATION_GOAL,
    }


# -- printing -------------------------------------------------------------------------------------


def print_tags(rows: list[dict[str, Any]]) -> None:
    print(
        "| tag | lines | time scale (limit) | speed SNR dB (≥ 20) | deviation mean / max mm"
        " (max ≤ 0.1) | drawing ratio (≤ 1.05) | job ratio | starvation (0) |"
        " stream B/s (% of link) | needed B/s mean / busiest s (% of link) | wall s | speed-up |"
    )
    print("|---|---:|---|---:|---|---:|---:|---:|---|---|---:|---:|")
    for row in rows:
        g = goals(row)
        cap = row["capacity"]
        print(
            f"| {row['tag']} | {row['lines']:,} | {row['time_scale']:.2f} ({row['limit']}) |"
            f" {row['snr_db']:.1f} {mark(g['snr'])} |"
            f" {row['dev_mean_mm']:.4f} / {row['dev_max_mm']:.4f} {mark(g['dev'])} |"
            f" {row['drawing_ratio']:.3f} {mark(g['drawing'])} |"
            f" {row['job_ratio']:.3f} {mark(g['job'])} |"
            f" {row['starvation']} {mark(g['starvation'])} |"
            f" {row['rate']:,.0f} ({100 * row['rate'] / cap:.0f} %) |"
            f" {row['need']:,.0f} / {row['need_peak']:,.0f}"
            f" ({100 * row['need'] / cap:.0f} / {100 * row['need_peak'] / cap:.0f} %) |"
            f" {row['wall_s']:.2f} | {row['speedup']:.0f} x |"
        )


def print_sweep(rows: list[dict[str, Any]]) -> None:
    print(
        "| dt ms | lines | time scale (limit) | pen-down G-code s | speed SNR dB"
        " | deviation max mm | drawing ratio | job ratio | starvation |"
        " needed B/s mean / busiest s (% of link) | stream B/s (% of link) | wall s |"
    )
    print("|---:|---:|---|---:|---:|---:|---:|---:|---:|---|---|---:|")
    for row in rows:
        g = goals(row)
        cap = row["capacity"]
        print(
            f"| {1000 * row['dt']:g} | {row['lines']:,} |"
            f" {row['time_scale']:.2f} ({row['limit']}) | {row['drawing_s']:.1f} |"
            f" {row['snr_db']:.1f} {mark(g['snr'])} | {row['dev_max_mm']:.4f} {mark(g['dev'])} |"
            f" {row['drawing_ratio']:.3f} {mark(g['drawing'])} |"
            f" {row['job_ratio']:.3f} {mark(g['job'])} |"
            f" {row['starvation']} {mark(g['starvation'])} |"
            f" {row['need']:,.0f} / {row['need_peak']:,.0f}"
            f" ({100 * row['need'] / cap:.0f} / {100 * row['need_peak'] / cap:.0f} %) |"
            f" {row['rate']:,.0f} ({100 * row['rate'] / cap:.0f} %) | {row['wall_s']:.2f} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dt", type=float, default=0.01, help="setpoint time step, s")
    parser.add_argument("--gml", type=int, default=5, help="GML tags from ../shared/data")
    parser.add_argument("--data", type=Path, default=DATA, help="the shared data folder")
    parser.add_argument(
        "--sweep-dt", default="", help="time steps for the sweep, s, e.g. 0.005,0.01,0.02"
    )
    parser.add_argument("--sweep-tag", default="dusttag-142.json", help="tag of the sweep")
    parser.add_argument("--csv", type=Path, help="write every row to this CSV file")
    parser.add_argument("--keep", type=Path, help="keep the run folders under this directory")
    args = parser.parse_args()

    tags = example_tags() + gml_tags(args.data, args.gml)
    rows: list[dict[str, Any]] = []
    failures: list[str] = []
    loaded: dict[str, tagbot.Tag] = {}
    for name, load in tags:
        try:
            tag = loaded[name] = load()
            rows.append({"part": "tags", **run_tag(name, tag, args.dt, args.keep)})
        except Exception as e:  # a failure is a figure, never dropped
            failures.append(f"{name}: {type(e).__name__}: {e}")

    print(
        f"Development tags through the simulated Grbl, 115200 baud, dt = {1000 * args.dt:g} ms"
        " (✓ goal met, ✗ missed)"
    )
    print_tags(rows)
    for failure in failures:
        print(f"FAILED {failure}")
    if rows:
        totals = {k: sum(r[k] for r in rows) for k in ("executed_s", "wall_s")}
        met = {k: sum(goals(r)[k] for r in rows) for k in goals(rows[0])}
        print(
            f"\n{len(rows)} tags, {totals['executed_s']:.0f} s of machine time simulated in"
            f" {totals['wall_s']:.1f} s wall ({totals['executed_s'] / totals['wall_s']:.0f} x)."
            " Goals met: " + ", ".join(f"{k} {v}/{len(rows)}" for k, v in met.items()) + "."
        )

    if args.sweep_dt:
        steps = [float(s) for s in args.sweep_dt.split(",") if s.strip()]
        name = args.sweep_tag
        if name not in loaded:
            known = dict(tags)
            if name not in known:
                raise SystemExit(f"--sweep-tag: unknown tag {name!r} (known: {', '.join(known)})")
            loaded[name] = known[name]()
        sweep = [run_tag(name, loaded[name], dt, args.keep) for dt in steps]
        rows += [{"part": "sweep", **row} for row in sweep]
        print(f"\nTime-step sweep on {name} (same profile, only motion.dt changed)")
        print_sweep(sweep)

    if args.csv and rows:
        fields = list(rows[0])
        with open(args.csv, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
