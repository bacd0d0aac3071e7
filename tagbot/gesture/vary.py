"""Variations of a tag (paper §7): many plausible instances from one plan.

Each instance perturbs, at random but reproducibly from a seed, what a writer varies from one
tag to the next: where the virtual targets fall, the tag's proportions (x and y scale), the
rhythm (each stroke's onset delay) and the curvature (each stroke's tangent deviations). The
default amplitudes keep a tag readable.

Two things a variation keeps:

- **The pen lifts**, from one plan's lift-off to the next plan's touch-down
  (:meth:`~tagbot.model.plan.Plan.ink_window`; their motions may overlap in the air).
- **The inked part of each plan's motion.** A plan with an ``ink`` window touches down and lifts off
  at the same fractions of its path length as the original (path: the pen's whole motion from the
  plan's start to its end, ink and air). Where the original pen rests there (before the motion
  starts, after it ends), the touch-down (lift-off) keeps its time before the motion's start
  (after its end). So a varied rhythm moves the window with the strokes instead of inking the air.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from tagbot.errors import PlanError
from tagbot.model.motion import evaluate_plan
from tagbot.model.plan import PHI_LIMIT, Model, Plan, Tag

REACH = 0.1
"""How far apart (a fraction of the tag's size) two targets' displacements stop moving together:
the field's correlation length. A writer's hand drifts over a whole letter; a tiny loop between
two close targets keeps its size (displaced independently, a 0.4 mm near-circle stroke grew into a
balloon several mm across)."""
FIELD_WAVES = 32
"""Random waves summed into the displacement field (random Fourier features of a Gaussian
correlation)."""
PATH_NODES = 512
"""Evaluations of the pen's speed per stroke window when a plan's path length is integrated."""


@dataclass(frozen=True)
class Variation:
    """Standard deviations of the perturbations (all relative, so units do not matter)."""

    position: float = 0.012
    """Target displacement, as a fraction of the tag's size: a smooth field over the tag (see
    :data:`REACH`), so that targets close together move together."""
    scale: float = 0.04
    """Log-scale of the tag's width and height, independently."""
    dt: float = 0.12
    """Log-scale of each stroke's onset delay."""
    phi: float = 0.12
    """Relative change of each stroke's tangent deviations."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (np.isfinite(value) and value >= 0):
                raise PlanError(f"{f.name}: must be a finite amplitude >= 0, got {value!r}")


def new_seed() -> int:
    """A fresh random seed (to print, so that a run can be repeated)."""
    return int(np.random.SeedSequence().entropy % (2**63))


def vary(tag: Tag, count: int, seed: int, variation: Variation | None = None) -> list[Tag]:
    """``count`` instances of ``tag``; the same seed gives the same instances."""
    return list(iter_vary(tag, count, seed, variation))


def iter_vary(tag: Tag, count: int, seed: int, variation: Variation | None = None) -> Iterator[Tag]:
    """:func:`vary`'s instances one at a time, in bounded memory whatever ``count``."""
    if int(count) != count or count < 1:
        raise PlanError(f"count: must be a whole number >= 1, got {count!r}")
    if int(seed) != seed or seed < 0:
        raise PlanError(f"seed: must be a whole number >= 0, got {seed!r}")
    variation = variation or Variation()
    root = np.random.SeedSequence(int(seed))
    for _ in range(int(count)):
        # spawn(1) n times gives the same children as spawn(n): instance i never depends on count.
        (stream,) = root.spawn(1)
        yield _instance(tag, np.random.default_rng(stream), variation)


def lifts(tag: Tag) -> list[float]:
    """Each pen lift of ``tag``, seconds from a plan's lift-off to the next one's touch-down."""
    size = tag.size
    return [
        later.ink_window(size)[0] - earlier.ink_window(size)[1]
        for earlier, later in itertools.pairwise(tag.plans)
    ]


def in_order(
    plans: Sequence[Plan], lifts: Sequence[float], model: Model = "gamma", units: str = "mm"
) -> Tag:
    """A tag drawing ``plans`` in order, plan ``k + 1`` touching down ``lifts[k]`` seconds after
    plan ``k`` lifts off (the first keeps its start; an approach in the air may start before the
    previous plan's motion, or the previous plan, does)."""
    if len(lifts) != len(plans) - 1:
        raise PlanError(f"lifts: expected {len(plans) - 1} (one per pen lift), got {len(lifts)}")
    gaps = np.asarray(lifts, dtype=float)
    if np.any(~np.isfinite(gaps)) or np.any(gaps < 0):
        raise PlanError(f"lifts: must be finite and >= 0, got {gaps.tolist()}")
    points = np.concatenate([plan.targets for plan in plans])
    size = float(np.hypot(*np.ptp(points, axis=0)))
    placed = [plans[0]]
    for plan, gap in zip(plans[1:], gaps.tolist(), strict=True):
        down = plan.ink[0] if plan.ink is not None else 0.0
        lift_off = placed[-1].ink_window(size)[1]
        placed.append(plan.at(lift_off + gap - down))
    return Tag(tuple(placed), model, units)


def path_length(plan: Plan, size: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Times from when ``plan``'s pen starts moving (its first stroke window opens) to when its
    motion ends, and the path length travelled by each: the exact speed integrated by the
    trapezoid rule on :data:`PATH_NODES` nodes per stroke window (a brief stroke gets as many
    as a long one). ``size``: the tag's, for the windows' tolerance."""
    t_on, t_off = plan.windows(size)
    t = np.unique(np.linspace(t_on, t_off, PATH_NODES).ravel())
    _, v = evaluate_plan(plan, t, size)
    speed = np.hypot(v[:, 0], v[:, 1])
    s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
    return t, s


def ink_fractions(plan: Plan, size: float) -> tuple[float, float]:
    """The fractions of ``plan``'s path length travelled when its pen touches down and lifts off
    (``(0, 1)`` without an ``ink`` window). ``size``: the tag's."""
    t, s = path_length(plan, size)
    down, up = plan.ink_window(size)
    return float(np.interp(down, t, s) / s[-1]), float(np.interp(up, t, s) / s[-1])


def keep_ink(original: Plan, varied: Plan, size: float, varied_size: float) -> Plan:
    """``varied`` with the ``ink`` window that inks the same part of its motion as ``original``'s
    does (see the module docstring); ``size``, ``varied_size``: their tags' sizes."""
    if original.ink is None:
        return varied
    t, s = path_length(original, size)
    t2, s2 = path_length(varied, varied_size)
    window = []
    for edge in (original.start + original.ink[0], original.start + original.ink[1]):
        if edge <= t[0]:  # resting on the first target: the same wait before the motion starts
            at = t2[0] - (t[0] - edge)
        elif edge >= t[-1]:  # resting on the last target: the same stay after the motion ends
            at = t2[-1] + (edge - t[-1])
        else:
            at = _time_at(t2, s2, float(np.interp(edge, t, s)) / s[-1] * s2[-1])
        window.append(max(at - varied.start, 0.0))
    fields = (varied.dt, varied.mu, varied.sigma, varied.phi1, varied.phi2)
    return Plan(varied.targets, *fields, varied.start, (window[0], window[1]))


def _time_at(t: NDArray[np.float64], s: NDArray[np.float64], length: float) -> float:
    """The first time the pen has travelled ``length`` (``s`` non-decreasing, linear between
    nodes)."""
    i = int(np.clip(np.searchsorted(s, length, side="left"), 1, len(s) - 1))
    ds = s[i] - s[i - 1]
    return float(t[i - 1] + (t[i] - t[i - 1]) * ((length - s[i - 1]) / ds if ds > 0 else 0.0))


def _displacement(
    rng: np.random.Generator, amplitude: float, reach: float
) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """A random smooth displacement field: at any point, each coordinate normal with standard
    deviation ``amplitude``; two points ``d`` apart correlate as ``exp(−d² / (2 reach²))``."""
    waves = rng.normal(0.0, 1.0 / max(reach, 1e-300), (FIELD_WAVES, 2))
    phases = rng.uniform(0.0, 2.0 * np.pi, FIELD_WAVES)
    weights = rng.normal(0.0, amplitude * np.sqrt(2.0 / FIELD_WAVES), (FIELD_WAVES, 2))
    return lambda points: np.cos(points @ waves.T + phases) @ weights


def _bent(phi: NDArray[np.float64], bend: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tangent deviations ``phi`` times ``bend``, no larger than the fits make them
    (:data:`~tagbot.model.plan.PHI_LIMIT`) or than they were: towards ±π a Euler spiral
    between two fixed targets grows without bound (a deviation of 3.0 bent to π − 10⁻⁶ drew a
    stroke two million times the tag's size)."""
    limit = np.maximum(PHI_LIMIT, np.abs(phi))
    return np.clip(phi * bend, -limit, limit)


def _instance(tag: Tag, rng: np.random.Generator, v: Variation) -> Tag:
    size = tag.size
    points = np.concatenate([plan.targets for plan in tag.plans])
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    stretch = np.exp(rng.normal(0.0, v.scale, 2))
    displace = _displacement(rng, v.position * size, REACH * size)
    varied: list[Plan] = []
    for plan in tag.plans:
        targets = centre + (plan.targets - centre) * stretch
        targets = targets + displace(plan.targets)
        dt = plan.dt * np.exp(rng.normal(0.0, v.dt, plan.n_strokes))
        bend = 1.0 + rng.normal(0.0, v.phi, plan.n_strokes)
        # Arcs stay arcs (one factor for both ends); spirals vary each end on its own.
        bend2 = np.where(plan.arcs, bend, 1.0 + rng.normal(0.0, v.phi, plan.n_strokes))
        phi1, phi2 = _bent(plan.phi1, bend), _bent(plan.phi2, bend2)
        varied.append(Plan(targets, dt, plan.mu, plan.sigma, phi1, phi2, plan.start))
    points = np.concatenate([plan.targets for plan in varied])
    varied_size = float(np.hypot(*np.ptp(points, axis=0)))
    plans = [keep_ink(a, b, size, varied_size) for a, b in zip(tag.plans, varied, strict=True)]
    return in_order(plans, lifts(tag), tag.model, tag.units)
