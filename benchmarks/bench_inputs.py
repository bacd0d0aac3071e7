"""Load every GML development capture and print what tagbot reads from it.

Run from the repository root::

    python benchmarks/bench_inputs.py [DIR] [--png OUT_DIR] [--fuzz N] [--corpus]

``DIR`` defaults to ``../shared/data/gml/dev`` (the real captures kept beside the repository; they
are not part of it and the tests never read them). For each file it prints the number of traces
and points, the drawing's size in millimetres, the timing (duration, or "untimed") and the load
time. ``--png`` also draws each file's traces into ``OUT_DIR/<file>.png`` (needs matplotlib, which
is not a tagbot dependency) to check orientation and aspect by eye. Exits with status 1 if any
file fails to load.

``--fuzz N`` then mutates each file N times (absurd numbers, repeated or dropped spans, cuts: the
suite's fuzz test's mutations) and reads, fits and reports each copy, printing the worst wall time
per case and what ended in an error. ``--corpus`` times ``tagbot fit DIR -o TMP --jobs J`` for
J = 1 and 2 (whole command, worker start-up included) and prints the speed-up.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from tagbot.errors import InputError
from tagbot.inputs import load_traces

DEFAULT_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "gml" / "dev"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dir", nargs="?", type=Path, default=DEFAULT_DIR)
    parser.add_argument("--png", type=Path, help="draw each file's traces into this folder")
    parser.add_argument("--fuzz", type=int, default=0, help="mutated copies per file to fit")
    parser.add_argument("--corpus", action="store_true", help="time corpus mode, 1 and 2 jobs")
    args = parser.parse_args()
    files = sorted(p for p in args.dir.iterdir() if p.suffix in (".gml", ".json", ".svg"))
    if not files:
        print(f"no input files in {args.dir}", file=sys.stderr)
        return 1
    failed = 0
    print(f"{'file':46} {'traces':>6} {'points':>6} {'size mm':>11} {'timing':>11} {'load':>7}")
    for path in files:
        start = time.perf_counter()
        try:
            traces = load_traces(path)
        except InputError as e:
            failed += 1
            print(f"{path.name[:46]:46} FAILED: {e}")
            continue
        elapsed = time.perf_counter() - start
        points = np.concatenate([tr.xy for tr in traces])
        width, height = np.ptp(points, axis=0)
        timing = "untimed" if traces[0].t is None else f"{traces[-1].t[-1]:.2f} s"
        print(
            f"{path.name[:46]:46} {len(traces):6d} {len(points):6d} "
            f"{width:5.0f} x{height:4.0f} {timing:>11} {elapsed * 1e3:5.1f} ms"
        )
        if args.png:
            draw(traces, args.png / f"{path.name}.png", path.name)
    print(f"{len(files) - failed} of {len(files)} files loaded")
    if args.fuzz:
        fuzz(files, args.fuzz)
    if args.corpus:
        corpus(args.dir)
    return 1 if failed else 0


def fuzz(files: list[Path], count: int) -> None:
    """Read, fit and report ``count`` mutated copies of each file; print the worst times."""
    import random

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_fuzz_fit import mutate

    from tagbot.errors import TagbotError
    from tagbot.gesture import fit
    from tagbot.inputs import read_traces_bytes
    from tagbot.metrics import fit_report

    rng = random.Random(0)
    ops = ["number", "number", "spread", "repeat", "drop", "cut"]
    times, outcomes = [], {"fitted": 0, "error": 0}
    for path in files:
        data = path.read_bytes()
        for _ in range(count):
            edits = [
                (rng.choice(ops), rng.randrange(1 << 20), rng.randrange(256))
                for _ in range(rng.randint(1, 6))
            ]
            case = mutate(data, edits)
            start = time.perf_counter()
            try:
                traces = read_traces_bytes(case, path.name)
                fit_report(traces, fit(traces))
                outcomes["fitted"] += 1
            except TagbotError:
                outcomes["error"] += 1
            times.append((time.perf_counter() - start, path.name))
    times.sort(reverse=True)
    seconds = np.array([t for t, _ in times])
    print(
        f"fuzz: {len(times)} cases ({outcomes['fitted']} fitted, {outcomes['error']} clear"
        f" errors); wall time median {np.median(seconds):.3f} s, p99"
        f" {np.percentile(seconds, 99):.2f} s, worst {seconds[0]:.2f} s ({times[0][1]})"
    )


def corpus(folder: Path) -> None:
    """Time the whole ``tagbot fit`` corpus command with 1 and 2 worker processes."""
    import subprocess
    import tempfile

    seconds = {}
    for jobs in (1, 2):
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "tagbot", "fit", str(folder), "-o", out, "-j", str(jobs)],
                check=False,
                capture_output=True,
            )
            seconds[jobs] = time.perf_counter() - start
    print(
        f"corpus: tagbot fit {folder.name}/ --jobs 1 {seconds[1]:.1f} s, --jobs 2"
        f" {seconds[2]:.1f} s, speed-up {seconds[1] / seconds[2]:.2f}x"
    )


def draw(traces, out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 4))
    for tr in traces:
        ax.plot(tr.xy[:, 0], tr.xy[:, 1], "-", lw=1.2)
        ax.plot(tr.xy[:1, 0], tr.xy[:1, 1], "k.", ms=3)
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=8)
    fig.savefig(out, dpi=80)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
