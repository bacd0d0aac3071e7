"""Variations of a tag (paper §7): many plausible instances from one plan.

Each instance perturbs, at random but reproducibly from a seed, what a writer varies from one
tag to the next: where the virtual targets fall, the tag's proportions (x and y scale), the
rhythm (each stroke's onset delay) and the curvature (each stroke's tangent deviations). The
default amplitudes keep a tag readable; the pen lifts keep their durations.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, fields

import numpy as np

from tagbot.errors import PlanError
from tagbot.model.plan import Plan, Tag, sequence


@dataclass(frozen=True)
class Variation:
    """Standard deviations of the perturbations (all relative, so units do not matter)."""

    position: float = 0.012
    """Target displacement, as a fraction of the tag's size."""
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


def _instance(tag: Tag, rng: np.random.Generator, v: Variation) -> Tag:
    size = tag.size
    points = np.concatenate([plan.targets for plan in tag.plans])
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    stretch = np.exp(rng.normal(0.0, v.scale, 2))
    lifts = [later.start - earlier.end(size) for earlier, later in itertools.pairwise(tag.plans)]
    plans: list[Plan] = []
    for plan in tag.plans:
        targets = centre + (plan.targets - centre) * stretch
        targets = targets + rng.normal(0.0, v.position * size, targets.shape)
        dt = plan.dt * np.exp(rng.normal(0.0, v.dt, plan.n_strokes))
        bend = 1.0 + rng.normal(0.0, v.phi, plan.n_strokes)
        # Arcs stay arcs (one factor for both ends); spirals vary each end on its own.
        bend2 = np.where(plan.arcs, bend, 1.0 + rng.normal(0.0, v.phi, plan.n_strokes))
        phi1 = np.clip(plan.phi1 * bend, -np.pi + 1e-6, np.pi - 1e-6)
        phi2 = np.clip(plan.phi2 * bend2, -np.pi + 1e-6, np.pi - 1e-6)
        plans.append(Plan(targets, dt, plan.mu, plan.sigma, phi1, phi2, plan.start, plan.ink))
    return sequence(plans, lifts, tag.model, tag.units)
