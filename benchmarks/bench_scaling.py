"""How the fit's time, memory and shape error grow with the points, and how fast a stop signal
ends a command (issue 29: bounded, interruptible work).

Run from the repository root (no data folder needed)::

    python benchmarks/bench_scaling.py [--sizes 1000,10000,100000] [--timings ignore,auto]
                                       [--limit 300] [--no-signals]

Inputs, made here and reproducible (seed 0):

* ``random``: n points uniform in a 1000 x 1000 square, one trace, 100 Hz time stamps (the
  outside tester's random GML);
* ``spiral``: a dense smooth Archimedean spiral of ten turns (radius 20 to 960) sampled at n
  points, 100 Hz time stamps.

Each case runs in a fresh process (its own peak RSS, from ``resource.getrusage``) after fitting
one small tag, so compiling or loading the kernels is not counted; a case over ``--limit``
seconds is stopped and reported as such. Printed per case: strokes, fit seconds (wall and the
process's CPU), peak RSS (MB) after the fit and after the report, shape error
(mean and max, % of the input's diagonal; ``tagbot.metrics.fit_report``). A fit the library
refuses (a tag lasting more than a tag may) prints the refusal with the seconds and memory it
took to get there.

Signal latency: a ``tagbot`` command spending minutes in one compiled loop gets SIGINT, SIGTERM
or SIGHUP; printed: seconds from the signal to the process's end, its status and last line.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time

CASE = textwrap.dedent(
    """
    import json, resource, sys, time
    import numpy as np
    from tagbot.errors import PlanError
    from tagbot.gesture import reconstruction
    from tagbot.inputs import Trace
    from tagbot.metrics import fit_report

    def peak():
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

    kind, n, timing = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    rng = np.random.default_rng(0)
    if kind == "random":
        xy = rng.uniform(0.0, 1000.0, (n, 2))
    else:
        theta = np.linspace(0.0, 20.0 * np.pi, n)
        radius = 20.0 + 940.0 * theta / theta[-1]
        xy = np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])
    trace = Trace(xy=xy, t=np.arange(n) * 0.01)
    reconstruction([np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]])], timing="ignore")
    started, cpu = time.perf_counter(), time.process_time()
    try:
        result = reconstruction([trace], timing=timing)
    except PlanError as e:
        print(json.dumps({"refused": str(e), "seconds": time.perf_counter() - started,
                          "cpu": time.process_time() - cpu, "rss_mb": peak()}))
        sys.exit(0)
    seconds, cpu = time.perf_counter() - started, time.process_time() - cpu
    fitted = peak()
    report = fit_report([trace], result.tag, timings=result.timings)
    print(json.dumps({
        "strokes": result.tag.n_strokes,
        "seconds": seconds,
        "cpu": cpu,
        "rss_mb": fitted,
        "report_rss_mb": peak(),
        "mean": 100 * report.shape.mean,
        "max": 100 * report.shape.max,
        "timing": report.timing or "geometric",
    }))
    """
)

SPIN = textwrap.dedent(
    """
    import sys
    import numpy as np
    from tagbot import cli
    from tagbot.gesture.contour_kernels import smooth

    @cli.cli.command("spin")
    def spin() -> None:
        smooth(np.zeros((4, 2)), np.ones(2), 0)
        n = 200_000
        print("ready", flush=True)
        smooth(np.random.rand(n, 2), np.ones(n) / n, 0)

    sys.exit(cli.main(["spin"]))
    """
)


def run_case(kind: str, n: int, timing: str, limit: float) -> str:
    """One line of figures for a case (or why there are none)."""
    try:
        done = subprocess.run(
            [sys.executable, "-c", CASE, kind, str(n), timing],
            capture_output=True,
            text=True,
            timeout=limit,
        )
    except subprocess.TimeoutExpired:
        return f"stopped after {limit:g} s"
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        return f"failed (status {done.returncode}): {last}"
    r = json.loads(done.stdout.strip().splitlines()[-1])
    if "refused" in r:
        return (
            f"refused after {r['seconds']:.1f} s (cpu {r['cpu']:.1f} s), peak {r['rss_mb']:.0f} MB:"
            f" {r['refused']}"
        )
    return (
        f"{r['strokes']:6d} strokes  fit {r['seconds']:7.2f} s (cpu {r['cpu']:7.2f} s)  "
        f"peak {r['rss_mb']:6.0f} MB ({r['report_rss_mb']:6.0f} with the report)  "
        f"shape mean {r['mean']:.3f} % max {r['max']:.2f} %  "
        f"({r['timing']})"
    )


def signal_latency(signum: int) -> str:
    """Seconds from ``signum`` to the end of a command inside a long compiled loop."""
    with tempfile.TemporaryDirectory() as folder:
        script = os.path.join(folder, "spin.py")
        with open(script, "w") as f:
            f.write(SPIN)
        process = subprocess.Popen(
            [sys.executable, script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        assert process.stdout is not None
        process.stdout.readline()
        time.sleep(0.5)
        sent = time.monotonic()
        process.send_signal(signum)
        _, err = process.communicate()
        latency = time.monotonic() - sent
    lines = err.strip().splitlines()
    last = lines[-1] if lines else "(no output)"
    return f"{latency:.3f} s, status {process.returncode}, {len(lines)} line: {last!r}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1000,10000,100000")
    parser.add_argument("--kinds", default="random,spiral")
    parser.add_argument("--timings", default="ignore,auto")
    parser.add_argument("--limit", type=float, default=300.0, help="Seconds per case at most.")
    parser.add_argument("--no-signals", action="store_true")
    args = parser.parse_args()
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}")
    for kind in args.kinds.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            for timing in args.timings.split(","):
                print(f"{kind:6s} {n:7d} {timing:6s}  {run_case(kind, n, timing, args.limit)}")
                sys.stdout.flush()
    if not args.no_signals:
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            print(f"{signal.Signals(signum).name:7s} in a compiled loop: {signal_latency(signum)}")


if __name__ == "__main__":
    main()
