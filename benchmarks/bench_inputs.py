"""Load every GML development capture and print what tagbot reads from it.

Run from the repository root::

    python benchmarks/bench_inputs.py [DIR] [--png OUT_DIR]

``DIR`` defaults to ``../shared/data/gml/dev`` (the real captures kept beside the repository; they
are not part of it and the tests never read them). For each file it prints the number of traces
and points, the drawing's size in millimetres, the timing (duration, or "untimed") and the load
time. ``--png`` also draws each file's traces into ``OUT_DIR/<file>.png`` (needs matplotlib, which
is not a tagbot dependency) to check orientation and aspect by eye. Exits with status 1 if any
file fails to load.
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
    return 1 if failed else 0


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
