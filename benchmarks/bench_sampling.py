"""Sampling throughput: active stroke-samples per second, against scipy.special.fresnel.

Run from the repository root::

    python benchmarks/bench_sampling.py [--strokes 400] [--dt 0.001] [--repeat 7]

An *active stroke-sample* is one (sample, stroke) pair inside the stroke's active window: the unit
of work of :func:`tagbot.model.motion.sample`. The reference is ``scipy.special.fresnel`` over the
same number of points, timed in the same run (machines are noisy; ratios within one run are what
count). Fresnel's cost depends on its argument (a rational approximation below 1.6, an asymptotic
series with trigonometry above), so the reference uses the very arguments the sampler evaluates on
the gamma tag, recorded and repeated to the same count; a second figure uses arguments spread
uniformly over [-8, 8] for comparison. The scaling check doubles both the number of strokes and
the duration (by doubling the number of plans) and reports the time ratio. The plans' spiral fits
are cached by the first call and timed separately.
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable

import numpy as np
from scipy.special import fresnel, ndtr

from tagbot.model import kernels
from tagbot.model.motion import sample_plan
from tagbot.model.plan import DEFAULT_MU, DEFAULT_SIGMA, Plan, Tag


def make_tag(plans: int, strokes_per_plan: int, seed: int, sigma_model: bool = False) -> Tag:
    """Random tags of plausible shape: ~30 mm steps, dt in [0.05, 0.3] s, tangents in ±2.5 rad."""
    rng = np.random.default_rng(seed)
    built: list[Plan] = []
    for _ in range(plans):
        m = strokes_per_plan + 1
        targets = np.cumsum(rng.normal(size=(m, 2)) * 30.0, axis=0)
        n = m - 1
        args = (
            targets,
            rng.uniform(0.05, 0.3, n),
            DEFAULT_MU + rng.normal(0.0, 0.1, n),
            DEFAULT_SIGMA * rng.uniform(0.8, 1.2, n),
        )
        start = built[-1].end(Tag(tuple(built)).size) + 0.3 if built else 0.0
        if sigma_model:
            plan = Plan.sigma_model(*args, rng.uniform(-2.5, 2.5, n), start)
        else:
            plan = Plan(*args, rng.uniform(-2.5, 2.5, n), rng.uniform(-2.5, 2.5, n), start)
        built.append(plan)
    return Tag(tuple(built), "sigma" if sigma_model else "gamma")


def active_pairs(tag: Tag, dt: float) -> int:
    """The number of (sample, stroke) pairs inside the strokes' windows."""
    total = 0
    for plan in tag.plans:
        t_on, t_off = plan.windows(tag.size)
        total += int(
            np.sum(np.floor((t_off - tag.start) / dt) - np.ceil((t_on - tag.start) / dt) + 1)
        )
    return total


def fresnel_arguments(tag: Tag, dt: float) -> np.ndarray:
    """The arguments at which the sampler evaluates Fresnel integrals while sampling ``tag``:
    one per (sample, active spiral stroke) pair, ``u = (s − s_c)/ρ`` (see tagbot.model.kernels)."""
    recorded: list[np.ndarray] = [np.zeros(0)]
    for k, plan in enumerate(tag.plans):
        t, _, _ = sample_plan(tag, k, dt)
        constants = plan.geometry.constants
        t_on, t_off = plan.windows(tag.size)
        for j in np.flatnonzero(constants[:, kernels.KIND] == kernels.SPIRAL):
            active = t[(t >= t_on[j]) & (t <= t_off[j])]
            w = ndtr((np.log(active - plan.onsets[j]) - plan.mu[j]) / plan.sigma[j])
            s = plan.geometry.length[j] * w
            recorded.append((s - constants[j, kernels.S_CENTRE]) * constants[j, kernels.INV_SCALE])
    return np.concatenate(recorded) if len(recorded) > 1 else np.zeros(1)


def best_times(fns: dict[str, Callable[[], object]], repeat: int) -> dict[str, float]:
    """Best wall-clock time of each function over ``repeat`` rounds, interleaved.

    Each round runs every function once, so drifts in the machine's speed hit all of them alike
    and their ratios stay meaningful. One warm-up round first.
    """
    best = {name: float("inf") for name in fns}
    for round_ in range(repeat + 1):
        for name, fn in fns.items():
            start = time.perf_counter()
            fn()
            elapsed = time.perf_counter() - start
            if round_:
                best[name] = min(best[name], elapsed)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--strokes", type=int, default=400, help="strokes in the base tag")
    parser.add_argument("--plans", type=int, default=8, help="plans in the base tag")
    parser.add_argument("--dt", type=float, default=0.001, help="time step, seconds")
    parser.add_argument("--repeat", type=int, default=15, help="timings per measurement (best)")
    args = parser.parse_args()

    print(
        f"machine: {platform.machine()} {platform.processor() or ''}"
        f" python {platform.python_version()}"
        f" numpy {np.__version__}"
    )
    print(f"base tag: {args.plans} plans, {args.strokes} strokes, dt = {args.dt * 1e3:g} ms\n")
    per_plan = max(1, args.strokes // args.plans)
    own_arguments = fresnel_arguments(make_tag(args.plans, per_plan, seed=1), args.dt)
    for model in ("gamma", "sigma"):
        sigma_model = model == "sigma"
        base = make_tag(args.plans, per_plan, seed=1, sigma_model=sigma_model)
        double = make_tag(2 * args.plans, per_plan, seed=1, sigma_model=sigma_model)

        fit_start = time.perf_counter()
        for plan in base.plans:
            plan.geometry  # noqa: B018 - fit and cache the spirals
        fit_time = time.perf_counter() - fit_start

        pairs = active_pairs(base, args.dt)
        u = np.resize(own_arguments, pairs)
        wide = np.random.default_rng(0).uniform(-8.0, 8.0, pairs)
        times = best_times(
            {
                "sample": lambda tag=base: tag.sample(args.dt),
                "fresnel": lambda u=u: fresnel(u),
                "wide": lambda wide=wide: fresnel(wide),
                "double": lambda tag=double: tag.sample(args.dt),
            },
            args.repeat,
        )
        t_sample, t_fresnel, t_wide, t_double = (
            times[k] for k in ("sample", "fresnel", "wide", "double")
        )
        samples = len(base.sample(args.dt))

        print(
            f"[{model}] {base.n_strokes} strokes, {samples} samples, {pairs} active stroke-samples"
            f" ({pairs / samples:.2f} strokes active per sample)"
        )
        print(f"  fit (once per plan, cached): {fit_time * 1e3:8.2f} ms")
        print(
            f"  sample:                      {t_sample * 1e3:8.2f} ms"
            f"  = {pairs / t_sample / 1e6:6.2f} M active stroke-samples/s"
        )
        print(
            f"  fresnel, sampler's arguments:{t_fresnel * 1e3:8.2f} ms"
            f"  = {pairs / t_fresnel / 1e6:6.2f} M/s"
            f"  (|u| median {np.median(np.abs(own_arguments)):.2f})"
        )
        print(
            f"  fresnel, uniform on [-8, 8]: {t_wide * 1e3:8.2f} ms"
            f"  = {pairs / t_wide / 1e6:6.2f} M/s"
        )
        print(
            f"  ratio sample / fresnel:      {t_sample / t_fresnel:8.2f}   (goal <= 2;"
            f" {t_sample / t_wide:.2f} against the uniform arguments)"
        )
        print(
            f"  2x strokes and duration:     {t_double * 1e3:8.2f} ms"
            f"  ratio {t_double / t_sample:.2f}   (goal <= 2.2)\n"
        )


if __name__ == "__main__":
    main()
