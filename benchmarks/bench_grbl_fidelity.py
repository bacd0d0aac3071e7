"""Fidelity of the simulated Grbl planner and stepper against the real Grbl 1.1h firmware.

Run from the repository root (needs ../shared/reference/grbl-1.1h)::

    python benchmarks/bench_grbl_fidelity.py [--transport both|recorded|wire]

The reference logs are serial transcripts of Grbl 1.1h (compiled as a host simulator) streamed
over a pseudo-terminal. They record what the host measured, not the G-code it sent, so the
programs are rebuilt from each log's summary line and name:

- ``shortsegs-{cc,sr}_n{N}_F6000[_lat5ms]``: from rest at (0, 0), ``G21 G90 G94``, then
  ``G1 X20 Y0 F6000`` and N chords of the circle of radius 20 about the origin, counter-clockwise
  from (20, 0) ("seg len" = 2π·20/N), coordinates with 3 decimals: N + 2 lines, as logged. The
  logged positions lie on that path, and the first 16 lines are acknowledged at once (one
  modal line + 15 planner blocks).
- ``g93_dt{dt}``: ``G93``, then one ``G1 X… F<60/dt>`` per setpoint of a 1 s bell-shaped speed
  profile over 50 mm, then ``G94``. The profile itself is not in the logs: it is reconstructed
  once from the ``dt0.005`` log (see :data:`G93_SPEED_KNOTS`) and used unchanged for all three
  logs, so the 2 ms and 20 ms runs are predictions.
- ``sendresp``, ``errorline``, ``hold``: the short protocol sessions, with Grbl's default
  settings (no ``$`` settings were sent in them).

Each program is replayed through :class:`sim.grbl.GrblExecutor` with the log's streaming mode,
character counting (``cc``: unacknowledged bytes ≤ 127) or send-and-wait (``sr``: next line after
each ``ok``, plus the host latency in the name). Two transports are modelled:

- ``wire``: 115200 baud, 10 bits per byte both ways (a real board's serial line), the device
  reading each line as soon as its last byte is in;
- ``recorded``: what the reference host and firmware simulator actually did. That setup moves
  serial bytes much faster than 115200 baud, but its firmware loop takes about 1 ms to read a
  line (the 5 ms host latency comes on top). The time per line is measured from the log itself:
  the mean gap between acknowledgements of lines that a first replay shows were accepted without
  waiting for a planner slot, so that motion does not gate them.

The ``wire`` figures are what a real board at 115200 baud would do with the same programs; they
differ from the logs where the stream is limited by the serial line (0.05 mm chords at F6000 need
more bytes per second than 115200 baud carries), which is a prediction, not a mismatch.

Reported per log: the host's "acked" time (last ``ok``), the host's "total"/"elapsed" time (idle
seen by its status polls, every 0.2 s or 20 ms after the last ``ok``), the end of motion (exact
in the simulation, bracketed between the last ``Run`` and first ``Idle`` poll in the log), and
how far the logged positions are ahead of the simulated ones, in milliseconds of motion, over
all ``Run`` status reports.
"""

from __future__ import annotations

import argparse
import itertools
import math
import re
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.grbl import Dwell, GrblExecutor, GrblSettings, MotionBlock

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT.parent / "shared" / "reference" / "grbl-1.1h"

RX_BUFFER = 127  # bytes the host keeps unacknowledged with character counting
BAUD_BYTE_TIME = 10.0 / 115200.0  # 8N1: start + 8 data + stop bits
OK_BYTES = 4  # "ok\r\n"

_STATUS = re.compile(r"<(\w+)(?::\d)?\|MPos:([-\d.]+),([-\d.]+),([-\d.]+)")
_LINE = re.compile(r"^\s*([\d.]+) (.*)$")


# -- logs -----------------------------------------------------------------------------------------


@dataclass
class Status:
    t: float
    state: str
    mpos: tuple[float, float, float]


@dataclass
class Log:
    name: str
    header: list[tuple[float, str]]
    raw: list[tuple[float, str]]

    def statuses(self) -> list[Status]:
        out = []
        for t, text in self.raw:
            m = _STATUS.search(text)
            if m:
                xyz = (float(m.group(2)), float(m.group(3)), float(m.group(4)))
                out.append(Status(t, m.group(1), xyz))
        return out

    def header_match(self, pattern: str) -> tuple[float, re.Match[str]]:
        for t, text in self.header:
            m = re.search(pattern, text)
            if m:
                return t, m
        raise ValueError(f"{self.name}: no header line matching {pattern!r}")

    def ok_times(self) -> list[float]:
        return [t for t, text in self.raw if text.strip() in ("ok",) or text.startswith("error:")]


def read_log(path: Path) -> Log:
    header: list[tuple[float, str]] = []
    raw: list[tuple[float, str]] = []
    target = header
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("----") and "raw transcript" in line:
            target = raw
            continue
        m = _LINE.match(line)
        if m:
            target.append((float(m.group(1)), m.group(2)))
    return Log(path.stem.replace("grblsim_1.1h_", ""), header, raw)


def plotter_settings(log: Log) -> GrblSettings:
    pairs = re.findall(r"'\$(\d+)=([\d.]+)', 'ok'", " ".join(text for _, text in log.header))
    return GrblSettings.from_dollar_settings({int(k): float(v) for k, v in pairs})


# -- a tiny G-code reader for the words these programs use ----------------------------------------


def parse_program(
    lines: list[str], start_mm: tuple[float, float, float]
) -> list[MotionBlock | Dwell | None]:
    """One item per line: a MotionBlock, a Dwell, or None for a line that only sets modes."""
    pos = list(start_mm)
    motion, inverse, feed = 0, False, None
    items: list[MotionBlock | Dwell | None] = []
    for line in lines:
        words = re.findall(r"([A-Z])([-+]?[\d.]+)", line.upper())
        axes: dict[str, float] = {}
        item: MotionBlock | Dwell | None = None
        dwell = None
        for letter, value in words:
            v = float(value)
            if letter == "G":
                if v in (0, 1):
                    motion = int(v)
                elif v == 93:
                    inverse = True
                elif v == 94:
                    inverse = False
                elif v == 4:
                    dwell = 0.0
            elif letter in "XYZ":
                axes[letter] = v
            elif letter == "F":
                feed = v
            elif letter == "P" and dwell is not None:
                dwell = v
        if dwell is not None:
            item = Dwell(dwell)
        elif axes:
            for i, letter in enumerate("XYZ"):
                pos[i] = axes.get(letter, pos[i])
            target = (pos[0], pos[1], pos[2])
            if motion == 0:
                item = MotionBlock(target, rapid=True)
            elif inverse:
                item = MotionBlock(target, inverse_time_per_min=feed)
            else:
                item = MotionBlock(target, feed_mm_per_min=feed)
            if inverse:
                feed = None  # G93 needs F on every line
        items.append(item)
    return items


# -- programs -------------------------------------------------------------------------------------


def fmt(v: float) -> str:
    s = f"{v:.3f}"
    return "0.000" if s == "-0.000" else s


def circle_program(n: int, feed: float) -> list[str]:
    lines = ["G21 G90 G94", f"G1 X20.000 Y0.000 F{feed:g}"]
    for k in range(1, n + 1):
        a = 2.0 * math.pi * k / n
        lines.append(f"G1 X{fmt(20.0 * math.cos(a))} Y{fmt(20.0 * math.sin(a))}")
    return lines


# The g93 logs do not record their setpoints, only that they sample "a 1 s lognormal-like speed
# profile" over 50 mm. No lognormal (shifted, mirrored or not) fits the logged positions well, so
# the profile is reconstructed without a model: the speed is piecewise linear through these
# relative values at t = 0, 1/12, …, 1 s (zero at both ends), integrated and scaled to 50 mm. The
# values were fitted (Powell, least squares) to the dt = 5 ms log's Run positions and FS speeds
# through this very simulation, and are used unchanged for the 2 ms and 20 ms logs.
G93_SPEED_KNOTS = (
    0.0,
    0.0656,
    0.3007,
    0.5242,
    0.7778,
    0.9119,
    1.0,
    0.9231,
    0.7133,
    0.4719,
    0.2416,
    0.0475,
    0.0,
)


def g93_profile(t: np.ndarray, knots: tuple[float, ...] = G93_SPEED_KNOTS) -> np.ndarray:
    """Position (mm) of the reconstructed profile at times ``t`` in [0, 1] s."""
    grid = np.linspace(0.0, 1.0, 4001)
    speed = np.interp(grid, np.linspace(0.0, 1.0, len(knots)), knots)
    x = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(grid))])
    return np.interp(t, grid, 50.0 * x / x[-1])


def g93_program(dt: float, knots: tuple[float, ...] = G93_SPEED_KNOTS) -> list[str]:
    n = round(1.0 / dt)
    x = g93_profile(dt * np.arange(1, n + 1), knots)
    x[-1] = 50.0
    return ["G93", *(f"G1 X{fmt(v)} F{60.0 / dt:g}" for v in x), "G94"]


# -- host + serial line + firmware loop -----------------------------------------------------------


@dataclass
class Transport:
    name: str
    byte_time: float  # wire time per byte, both directions
    line_time: float  # firmware time to read one line, once it is in
    latency: float = 0.0  # extra host delay before each send-and-wait line


@dataclass
class Run:
    ok_recv: list[float]
    end: float
    executor: GrblExecutor
    lines: list[str] = field(repr=False)
    waited: list[bool] = field(repr=False)
    probes: list[Probe] = field(repr=False)


@dataclass
class Probe:
    """What a status report would show at time ``t``."""

    t: float
    state: str
    mpos: tuple[float, float, float]
    free_blocks: int
    rate_mm_per_min: float


def stream(
    settings: GrblSettings,
    lines: list[str],
    mode: str,
    transport: Transport,
    start_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
    probes: list[float] | None = None,
) -> Run:
    """Replay ``lines`` from time 0 with character counting (``cc``) or send-and-wait (``sr``)."""
    items = parse_program(lines, start_mm)
    ex = GrblExecutor(settings, start_mm, auto_start=False)
    size = [len(line) + 1 for line in lines]
    ok_recv: list[float] = []
    wire_free = 0.0
    device_free = 0.0
    sent = 0.0
    window_start, window_bytes = 0, 0
    waited: list[bool] = []
    arrivals: list[float] = []

    def arrival(i: int) -> float:
        # When line i is fully in the firmware's receive buffer (needs acks of earlier lines).
        nonlocal sent, wire_free, window_start, window_bytes
        if mode == "sr":
            sent = ok_recv[-1] + transport.latency if i else 0.0
        else:
            window_bytes += size[i]
            while window_bytes > RX_BUFFER:
                window_bytes -= size[window_start]
                sent = max(sent, ok_recv[window_start])
                window_start += 1
        wire_free = max(sent, wire_free) + size[i] * transport.byte_time
        return wire_free

    probe_times = sorted(probes or [])
    probed: list[Probe] = []

    def run_until(t: float, until: Callable[[], bool] | None = None) -> None:
        # Advance the executor, taking a status snapshot at every probe time passed on the way.
        while len(probed) < len(probe_times) and probe_times[len(probed)] <= t:
            if ex.run_until(probe_times[len(probed)], until):
                return
            probed.append(
                Probe(ex.now, ex.state, ex.position_mm, ex.free_blocks, ex.reported_rate_mm_per_min)
            )
        ex.run_until(t, until)

    for i, item in enumerate(items):
        if len(arrivals) <= i:
            arrivals.append(arrival(i))
        start = max(arrivals[i], device_free) + transport.line_time
        run_until(start)
        accepted = item is None or ex.submit(item)
        if not accepted:
            run_until(math.inf, until=lambda item=item: ex.submit(item))
        waited.append(not accepted)
        device_free = ex.now
        ok_recv.append(ex.now + OK_BYTES * transport.byte_time)
        # Grbl starts motion when its parser finds the receive buffer empty.
        if mode == "cc" and i + 1 < len(items):
            arrivals.append(arrival(i + 1))
            if arrivals[i + 1] > device_free:
                ex.cycle_start()
        else:
            ex.cycle_start()
    run_until(math.inf, until=lambda: ex.idle)
    end = ex.now
    run_until(max(probe_times, default=end))
    return Run(ok_recv, end, ex, lines, waited, probed)


def measured_line_time(log: Log, t0: float, free: list[bool] | None = None) -> float:
    """Mean gap between the log's acknowledgements of lines the planner took at once.

    ``free[i]`` says whether line ``i`` was accepted without waiting for a planner slot (from a
    first replay); without it, the first 14 acknowledgements are used (the planner fills later).
    """
    oks = [t for t in log.ok_times() if t >= t0 - 1e-3]
    if free is None:
        gaps = [b - a for a, b in itertools.pairwise(oks[:14])]
    else:
        gaps = [
            oks[i] - oks[i - 1]
            for i in range(1, min(len(oks), len(free)))
            if free[i] and free[i - 1]
        ]
    # The log's times have 1 ms resolution: average the gaps near the median, not the median.
    mid = statistics.median(gaps)
    return statistics.fmean(g for g in gaps if 0.5 * mid <= g <= 1.5 * mid)


# -- comparing ------------------------------------------------------------------------------------


def path_position(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Arc length along a polyline of each point, searching forward from the previous point."""
    seg = vertices[1:] - vertices[:-1]
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    out = np.empty(len(points))
    k = 0
    for i, p in enumerate(points):
        best = (math.inf, k, 0.0)
        for j in range(k, min(k + 400, len(seg))):
            if seg_len[j] == 0:
                continue
            u = min(max(float(np.dot(p - vertices[j], seg[j]) / seg_len[j] ** 2), 0.0), 1.0)
            d = float(np.linalg.norm(vertices[j] + u * seg[j] - p))
            if d < best[0] - 1e-9:
                best = (d, j, u)
        k = best[1]
        out[i] = cum[k] + best[2] * seg_len[k]
    return out


@dataclass
class Comparison:
    name: str
    real_acked: float | None
    sim_acked: float | None
    real_total: float
    sim_total: float
    real_end_bracket: tuple[float, float]
    sim_end: float
    lead_ms: list[float]


def compare(
    log: Log,
    run: Run,
    t0: float,
    real_acked: float | None,
    real_total: float,
    vertices: np.ndarray,
    poll: float,
) -> Comparison:
    statuses = [s for s in log.statuses() if s.t >= t0 - 1e-3]
    runs = [s for s in statuses if s.state == "Run"]
    last_run = max((s.t for s in runs), default=t0) - t0
    first_idle = min(s.t for s in statuses if s.state == "Idle" and s.t - t0 > last_run) - t0
    # The host's idle detection: the first of its status polls (the log's own poll times, then
    # continuing at the same period) that finds the machine idle.
    acked = run.ok_recv[-1]
    polls = [s.t - t0 for s in statuses]
    while polls[-1] < run.end:
        polls.append(polls[-1] + poll)
    sim_total = min(t for t in polls if t >= run.end)
    # Position lead: real position at each Run report vs the simulated one at that time.
    t_knots, p_knots = run.executor.recorder.knots()  # type: ignore[union-attr]
    times = np.array([s.t - t0 for s in runs if s.t - t0 < run.end])
    lead: list[float] = []
    if len(times):
        real = np.array([s.mpos for s in runs if s.t - t0 < run.end])
        sim = np.column_stack([np.interp(times, t_knots, p_knots[:, i]) for i in range(3)])
        s_real = path_position(real, vertices)
        s_sim = path_position(sim, vertices)
        # Convert the distance lead into time with the simulated path speed around that time.
        dense_t = np.linspace(0.0, run.end, max(int(run.end / 0.001), 2))
        dense = np.column_stack([np.interp(dense_t, t_knots, p_knots[:, i]) for i in range(3)])
        s_dense = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
        s_dense += path_position(dense[:1], vertices)[0]
        s_at = np.interp(times, dense_t, s_dense)
        t_of_real = np.interp(s_at + (s_real - s_sim), s_dense, dense_t)
        lead = list(1000.0 * (t_of_real - times))
    return Comparison(
        log.name,
        real_acked,
        acked if real_acked is not None else None,
        real_total,
        sim_total,
        (last_run, first_idle),
        run.end,
        lead,
    )


# -- the cases ------------------------------------------------------------------------------------


def shortsegs_case(path: Path, settings: GrblSettings, transport_kind: str) -> Comparison:
    log = read_log(path)
    m = re.search(r"shortsegs-(cc|sr)_n(\d+)_F(\d+)(?:_lat(\d+)ms)?", log.name)
    assert m, log.name
    mode, n, feed = m.group(1), int(m.group(2)), float(m.group(3))
    latency = float(m.group(4) or 0) / 1000.0
    t_ack, ma = log.header_match(r"acked (\d+) lines in ([\d.]+) s")
    _, mt = log.header_match(r"total ([\d.]+)")
    real_acked = float(ma.group(2))
    t0 = t_ack - real_acked
    lines = circle_program(n, feed)
    assert len(lines) == int(ma.group(1)), (len(lines), ma.group(1))
    transport = make_transport(transport_kind, log, t0, latency)
    run = stream(settings, lines, mode, transport)
    if transport_kind == "recorded":
        # Second pass: the per-line time from every line the planner took without waiting.
        free = [not w for w in run.waited]
        transport = make_transport(transport_kind, log, t0, latency, free=free)
        run = stream(settings, lines, mode, transport)
    angles = 2.0 * math.pi * np.arange(0, n + 1) / n
    vertices = np.column_stack(
        [
            np.concatenate([[0.0], 20.0 * np.cos(angles)]),
            np.concatenate([[0.0], 20 * np.sin(angles)]),
        ]
    )
    vertices = np.column_stack([vertices, np.zeros(len(vertices))])
    return compare(log, run, t0, real_acked, float(mt.group(1)), vertices, poll=0.2)


def g93_case(path: Path, settings: GrblSettings, transport_kind: str) -> Comparison:
    log = read_log(path)
    dt = float(re.search(r"dt([\d.]+)", log.name).group(1))  # type: ignore[union-attr]
    t_idle, me = log.header_match(r"elapsed ([\d.]+)")
    elapsed = float(me.group(1))
    t0 = t_idle - elapsed
    transport = make_transport(transport_kind, log, t0, 0.0)
    run = stream(settings, g93_program(dt), "cc", transport)
    vertices = np.array([[-1.0, 0.0, 0.0], [51.0, 0.0, 0.0]])
    # The host polled every 20 ms after its last ok; its "elapsed" runs to the first Idle poll.
    return compare(log, run, t0, None, elapsed, vertices, poll=0.0202)


def protocol_cases(transport_kind: str) -> list[Comparison]:
    """sendresp / errorline: short send-and-wait sessions with Grbl's default settings."""
    out = []
    defaults = GrblSettings()
    for name, lines, start, total_pattern in (
        (
            "sendresp",
            ["G21 G90 G94", "G1 X10 Y0 F600", "G1 X10 Y10", "G1 X0 Y10", "G0 X0 Y0"],
            (0.0, 0.0, 0.0),
            r"total ([\d.]+)",
        ),
        ("errorline", ["G21 G90 G94", "G1 X5 F600", "G1 X0"], (23.764, 0.0, 0.0), None),
    ):
        log = read_log(REFERENCE / f"grblsim_1.1h_{name}.log")
        t_first = min(log.ok_times())
        t0 = t_first - 0.001
        t_idle, _ = log.header_match(r"idle:")
        real_total = t_idle - t0
        if total_pattern:
            _, mt = log.header_match(total_pattern)
            real_total = float(mt.group(1))
            t0 = t_idle - real_total
        transport = make_transport(transport_kind, log, t0, 0.0, default_line=0.001)
        run = stream(defaults, lines, "sr", transport, start)
        pts = [start]
        for item in parse_program(lines, start):
            if isinstance(item, MotionBlock):
                pts.append(item.target_mm)
        out.append(compare(log, run, t0, None, real_total, np.array(pts), poll=0.2))
    return out


def hold_case() -> dict[str, float]:
    """hold: G1 X30 F300 (defaults), '!' at 1.530 s, '~' at 3.534 s (log times)."""
    log = read_log(REFERENCE / "grblsim_1.1h_hold.log")
    t_start = log.ok_times()[-1]
    ex = GrblExecutor(GrblSettings())
    assert ex.submit(MotionBlock((30.0, 0.0, 0.0), feed_mm_per_min=300.0))
    statuses = {round(s.t, 3): s for s in log.statuses()}
    t_hold, t_resume = 1.530, 3.534
    ex.run_until(t_hold - t_start)
    before = ex.position_mm[0]
    ex.feed_hold()
    ex.run_until(2.531 - t_start)
    held = ex.position_mm[0]
    ex.run_until(t_resume - t_start)
    ex.resume()
    ex.run_until(4.034 - t_start)
    after = ex.position_mm[0]
    ex.run_until_idle()
    return {
        "x at hold (real 6.296)": before,
        "x held (real 7.748)": held,
        "held x - x at hold, real": statuses[2.531].mpos[0] - statuses[1.530].mpos[0],
        "held x - x at hold, sim": held - before,
        "x 0.5 s after resume (real 8.948)": after,
        "end of motion (real idle poll 8.640, last Run 8.439)": ex.now + t_start,
    }


def make_transport(
    kind: str,
    log: Log,
    t0: float,
    latency: float,
    default_line: float | None = None,
    free: list[bool] | None = None,
) -> Transport:
    if kind == "wire":
        return Transport("wire", BAUD_BYTE_TIME, 0.0, latency)
    line = default_line if default_line is not None else measured_line_time(log, t0, free)
    # The measured gap already contains the host's send latency in send-and-wait logs.
    return Transport("recorded", 0.0, max(line - latency, 0.0), latency)


# -- report ---------------------------------------------------------------------------------------


def ratio(sim: float | None, real: float | None) -> str:
    if sim is None or real is None:
        return "      -"
    return f"{sim / real:7.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--transport", choices=["both", "recorded", "wire"], default="both")
    args = parser.parse_args()
    if not REFERENCE.is_dir():
        raise SystemExit(f"reference logs not found: {REFERENCE}")
    settings = plotter_settings(read_log(REFERENCE / "grblsim_1.1h_setup-plotter.log"))
    print(f"settings from setup-plotter: {settings}")
    kinds = ["recorded", "wire"] if args.transport == "both" else [args.transport]
    for kind in kinds:
        print(f"\ntransport: {kind}")
        print(
            f"{'log':32s} {'acked real':>10s} {'sim':>7s} {'ratio':>7s}"
            f" {'total real':>10s} {'sim':>7s} {'ratio':>7s}"
            f" {'end: real in':>16s} {'sim':>7s} {'lead ms med/max':>16s}"
        )
        wall = time.perf_counter()
        cases: list[Comparison] = []
        for path in sorted(REFERENCE.glob("grblsim_1.1h_shortsegs-*.log")):
            cases.append(shortsegs_case(path, settings, kind))
        for path in sorted(REFERENCE.glob("grblsim_1.1h_g93_dt*.log")):
            cases.append(g93_case(path, settings, kind))
        cases += protocol_cases(kind)
        worst = 0.0
        for c in cases:
            lead = np.array(c.lead_ms) if c.lead_ms else np.array([0.0])
            lo, hi = c.real_end_bracket
            acked_real = f"{c.real_acked:10.3f}" if c.real_acked is not None else f"{'-':>10s}"
            acked_sim = f"{c.sim_acked:7.3f}" if c.sim_acked is not None else f"{'-':>7s}"
            print(
                f"{c.name:32s} {acked_real} {acked_sim} {ratio(c.sim_acked, c.real_acked)}"
                f" {c.real_total:10.3f} {c.sim_total:7.3f} {ratio(c.sim_total, c.real_total)}"
                f"   ({lo:5.3f}, {hi:5.3f}] {c.sim_end:7.3f}"
                f" {np.median(np.abs(lead)):7.1f}/{np.max(np.abs(lead)):6.1f}"
            )
            for sim_v, real_v in ((c.sim_acked, c.real_acked), (c.sim_total, c.real_total)):
                if sim_v is not None and real_v is not None:
                    worst = max(worst, abs(sim_v / real_v - 1.0))
        print(
            f"worst |sim/real - 1| over acked and total times: {100 * worst:.1f} %"
            f" (replayed {len(cases)} logs in {time.perf_counter() - wall:.2f} s)"
        )
    print("\nhold (defaults, G1 X30 F300; '!' at 1.530 s, '~' at 3.534 s):")
    for key, value in hold_case().items():
        print(f"  {key:55s} {value:8.3f}")


if __name__ == "__main__":
    main()
