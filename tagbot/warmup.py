"""Compile the kernels ahead of first use: numba caches them on disk, so later runs load them.

:func:`warm_up` runs the compute steps of ``tagbot demo`` and of the default ``fit``, ``sample``,
``vary`` and ``draw`` on the shipped examples: every kernel they reach is compiled, with the
argument types they really pass, and written to numba's cache beside its source file. tagbot's
build backend (:mod:`tagbot._build`) runs it while building a wheel, so that ``pip install .``
ships the machine's compiled kernels and a first ``tagbot demo`` does not wait for the compiler
(numba keys each cached kernel by its source's contents, the interpreter, numba's version and
the CPU, and compiles again whenever one of them differs). ``python -m tagbot.warmup`` does the
same for an installed or editable tagbot.
"""

from __future__ import annotations

import sys
import time
from importlib import resources

__all__ = ["EXAMPLES", "warm_up"]

EXAMPLES = ("hello-world-147.json", "dusttag-142.json")
"""The shipped timed captures the warm-up fits (the demo's and the README's)."""


def warm_up(verbose: bool = False) -> float:
    """Compile every kernel the common commands reach; return the seconds it took."""
    from tagbot.gesture import fit, vary
    from tagbot.inputs import read_traces_bytes
    from tagbot.metrics import densify, fit_report, stroke_report

    started = time.perf_counter()
    for name in EXAMPLES:
        data = (resources.files("tagbot") / "examples" / name).read_bytes()
        traces = read_traces_bytes(data, name)
        for model in ("gamma", "sigma"):
            for timing in ("auto", "ignore"):
                tag = fit(traces, model=model, timing=timing)
                fit_report(traces, tag)
                stroke_report(traces, tag)
                densify(traces[0].xy, 1.0)  # the machine comparisons' (tagbot draw)
                tag.sample(0.005)
                vary(tag, 2, seed=0)
        if verbose:
            print(f"warm-up: {name} in {time.perf_counter() - started:.1f} s", file=sys.stderr)
    return time.perf_counter() - started


if __name__ == "__main__":
    print(f"tagbot kernels compiled and cached in {warm_up(verbose=True):.1f} s")
