"""The DYNAMIXEL drawing arm: loop timing over a pseudo-terminal, fidelity on the example tags.

Run from the repository root::

    python benchmarks/bench_arm.py [--seconds 4] [--rates 100,200,500] [--skip-timing]

Three parts, each printed as a table:

1. **Loop timing** (real time): ``tagbot sim arm`` runs in a separate process (its own GIL, as a
   user would run it) and serves the default profile's chain (1 Mbps bus) on a pseudo-terminal;
   :class:`tagbot.arm.driver.ArmDriver` connects through the unmodified dynamixel-sdk and streams
   ``--seconds`` of smooth joint goals at each rate, reading present positions back at the
   profile's 100 Hz. Reported: the sustained rate (ticks ÷ wall time from the first to the last
   tick), the period jitter (|interval between tick starts − period|, p50/p99/max), the
   lateness after each deadline (p50/p99), late ticks (> ¼ period) and resyncs (deadlines moved
   on after a stall).
2. **Fidelity** (simulated time, in process): every development tag (``tagbot/examples/*.json``;
   trace files are fitted first) drawn with :func:`tagbot.arm.draw_arm` on the simulated chain at
   each rate; the simulator's 1 ms pen-tip recorder is compared with the planned setpoints by
   :func:`tagbot.metrics.compare_execution` (the measure ``tagbot draw`` reports): pen-down path
   deviation mean/max (mm) and speed SNR executed vs planned (dB; goals: ≤ 0.5 mm, ≥ 20 dB).
3. **IK throughput**: :meth:`tagbot.arm.Arm.ik` on 10⁶ reachable points, points per second.
"""

from __future__ import annotations

import argparse
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import tagbot
from tagbot.arm import Arm, ArmProfile, draw_arm, load_profile
from tagbot.arm.driver import ArmDriver
from tagbot.arm.kinematics import angles_to_ticks
from tagbot.metrics import compare_execution

EXAMPLES = Path(tagbot.__file__).parent / "examples"
SERVER = "from tagbot.arm.cli import sim_arm_command; sim_arm_command()"


def _goals(n: int, profile: ArmProfile) -> np.ndarray:
    """``(n, 3)`` smooth goals around the park pose (pen up): a slow Lissajous in joint space."""
    t = np.arange(n) * profile.period
    park = np.array(profile.park)
    shoulder, elbow = profile.joints
    a1 = park[0] + math.radians(20) * np.sin(2 * np.pi * 0.25 * t)
    a2 = park[1] + math.radians(15) * np.sin(2 * np.pi * 0.4 * t)
    pen = np.full(n, profile["pen.up"])
    return np.column_stack([angles_to_ticks(a1, shoulder), angles_to_ticks(a2, elbow), pen])


def timing(rates: list[int], seconds: float) -> list[dict[str, float]]:
    """Stream to a ``tagbot sim arm`` process over its pty at each rate; loop figures."""
    rows = []
    for rate in rates:
        profile = load_profile(None, [f"motion.rate={rate}"])
        server = subprocess.Popen(
            [sys.executable, "-c", SERVER], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
        )
        try:
            assert server.stdout is not None
            path = server.stdout.readline().decode().strip()
            goals = _goals(round(seconds * rate), profile)
            with ArmDriver(path, profile) as driver:
                driver.connect()
                driver.move_to(goals[0], 0.5)
                result = driver.stream(goals)
        finally:
            server.send_signal(signal.SIGINT)
            server.wait(timeout=10)
        s = result.scheduler
        assert s is not None
        woke = np.array(s.woke)
        jitter = np.abs(np.diff(woke) - profile.period) * 1e3
        late = np.array(s.lateness) * 1e3
        rows.append(
            {
                "rate": rate,
                "ticks": len(goals),
                "sustained": (len(woke) - 1) / (woke[-1] - woke[0]),
                "jitter50": float(np.percentile(jitter, 50)),
                "jitter99": float(np.percentile(jitter, 99)),
                "jittermax": float(jitter.max()),
                "late50": float(np.percentile(late, 50)),
                "late99": float(np.percentile(late, 99)),
                "late": s.late_ticks,
                "resyncs": s.resyncs,
                "reads": len(result.reads),
            }
        )
    return rows


def _tags() -> list[tuple[str, tagbot.Tag]]:
    from tagbot.source import load_tag

    return [(path.name, load_tag(str(path))) for path in sorted(EXAMPLES.glob("*.json"))]


def fidelity(rates: list[int]) -> list[dict[str, object]]:
    """Each example tag through the in-process simulator at each rate."""
    rows = []
    for name, tag in _tags():
        for rate in rates:
            profile = load_profile(None, [f"motion.rate={rate}"])
            start = time.perf_counter()
            run = draw_arm(tag, profile)
            wall = time.perf_counter() - start
            sp = run.setpoints
            planned = [(sp.t[sp.plan == k], sp.xy[sp.plan == k]) for k in range(len(tag.plans))]
            comparison = compare_execution(planned, run.executed)
            rows.append(
                {
                    "tag": name,
                    "rate": rate,
                    "ticks": run.stats["ticks_sent"],
                    "scale": sp.time_scale,
                    "size": sp.mm_per_unit,
                    "dev_mean": comparison.deviation_mean,
                    "dev_max": comparison.deviation_max,
                    "snr": comparison.speed_snr_db,
                    "track": run.stats["joint_tracking_error"]["max"],
                    "wall": wall,
                }
            )
    return rows


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="streaming time per rate")
    parser.add_argument("--rates", default="100,200,500", help="loop rates, Hz")
    parser.add_argument("--skip-timing", action="store_true", help="no real-time pty part")
    args = parser.parse_args()
    rates = [int(r) for r in args.rates.split(",")]

    if not args.skip_timing:
        print(f"Loop timing over a pty (tagbot sim arm in its own process), {args.seconds:g} s")
        print(
            "| rate Hz | ticks | sustained Hz | jitter p50 / p99 / max ms | lateness p50 / p99 ms"
            " | late | resyncs | read-backs |"
        )
        print("|---:|---:|---:|---|---|---:|---:|---:|")
        for row in timing(rates, args.seconds):
            print(
                f"| {row['rate']} | {row['ticks']} | {row['sustained']:.1f} |"
                f" {row['jitter50']:.3f} / {row['jitter99']:.3f} / {row['jittermax']:.2f} |"
                f" {row['late50']:.3f} / {row['late99']:.3f} | {row['late']} |"
                f" {row['resyncs']} | {row['reads']} |"
            )
        print()

    print("Fidelity on the example tags (in-process simulator, simulated time)")
    print(
        "| tag | rate Hz | ticks | time scale | mm/unit | path dev mean / max mm"
        " | speed SNR dB | joint tracking max ° | wall s |"
    )
    print("|---|---:|---:|---:|---:|---|---:|---:|---:|")
    for row in fidelity(rates):
        print(
            f"| {row['tag']} | {row['rate']} | {row['ticks']} | {row['scale']:.2f} |"
            f" {row['size']:.3g} | {row['dev_mean']:.3f} / {row['dev_max']:.3f} |"
            f" {row['snr']:.1f} | {row['track']:.3f} | {row['wall']:.2f} |"
        )
    print()
    print(f"IK throughput: {ik_throughput() / 1e6:.1f} M points/s")


if __name__ == "__main__":
    main()
