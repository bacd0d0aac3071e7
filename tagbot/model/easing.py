"""Run clocks: a machine draws each plan from rest to rest, even one whose pen touches down or
lifts off while moving (an ``ink`` window, :attr:`~tagbot.model.plan.Plan.ink`).

A run draws the tag-clock interval ``on .. off`` of one plan. Its clock ``u`` (seconds, before the
run's time scale ``s``: machine time is ``s·u``) maps to the tag's clock by

    τ(u) = on + R₁·S(u / R₁)                       0 ≤ u ≤ R₁       (easing in)
    τ(u) = on − R₁/2 + u                           in between       (the plan's own speed)
    τ(u) = off − R₂·S((U − u) / R₂)                U − R₂ ≤ u ≤ U   (easing out)

with ``S(x) = x³ − x⁴/2`` and ``U = off − on + (R₁ + R₂)/2``. The speed factor ``τ'(u) =
3x² − 2x³`` (smoothstep) rises from 0 to 1 with zero slope at both ends: the machine starts at
rest with no step in acceleration, follows the plan's path exactly, and after ``R₁`` moves at the
plan's own speed. That jerk-limited start suits machines whose servos follow goals (the arms).
Stepper machines start every move at a constant acceleration (Grbl's planner, the EBB's moves):
for them a run starts steadily, ``S(x) = x² − x³/3``, ``τ'(u) = 2x − x²`` (a constant
acceleration from rest that fades to none where it joins the plan's speed) and ``U = off − on +
(R₁ + R₂)/3``: the pen leaves its touch-down point about ``(R·d/v)^(1/2)`` rather than
``R^(2/3)·(d/v)^(1/3)`` after touching down (``d`` a motor step, ``v`` the plan's speed there),
so it rests on the paper less. ``R₁ = R₂ = 0`` (a plan drawn from rest to rest, as the paper's
are) is the identity ``τ = on + u``. A run eases in where its plan touches down moving and out
where it lifts off moving, over :data:`EASE` seconds (less in a shorter run), and moves at the
plan's speed in between: its middle keeps the writer's rhythm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.model.plan import Plan

Array = NDArray[np.float64]

EASE = 0.1
"""How long (s, on the run's clock before its time scale) a run eases from or to rest where its
plan touches down or lifts off moving; it covers half as long of the plan's own clock."""

_EDGE = 1e-9
"""A run edge within this of the ink window's edge (seconds) starts or ends there."""


def _ramp_share(jerk_limited: bool) -> float:
    """``S(1)``: the share of a ramp's length the plan's clock advances over it."""
    return 0.5 if jerk_limited else 2.0 / 3.0


@dataclass(frozen=True)
class RunClock:
    """The map from a run's clock ``u`` to the tag's clock (module docstring)."""

    on: float
    """The tag-clock instant the run starts drawing."""
    off: float
    """The tag-clock instant it stops."""
    ease_in: float = 0.0
    """``R₁``, s of the run's clock (0: the plan is at rest there)."""
    ease_out: float = 0.0
    """``R₂``."""
    jerk_limited: bool = True
    """True: ramps by smoothstep (no step in acceleration anywhere); False: from a constant
    acceleration at rest (module docstring)."""

    @property
    def _kept(self) -> float:
        return _ramp_share(self.jerk_limited)

    def _ramp(self, x: Array) -> tuple[Array, Array]:
        """``S(x)`` and ``S'(x)``."""
        if self.jerk_limited:
            return x**3 - 0.5 * x**4, 3 * x**2 - 2 * x**3
        return x**2 - x**3 / 3, 2 * x - x**2

    @property
    def duration(self) -> float:
        """``U``: the run's length on its clock, s before the time scale."""
        return max(self.off - self.on, 0.0) + (1.0 - self._kept) * (self.ease_in + self.ease_out)

    @property
    def tag_start(self) -> float:
        """The tag-clock instant the run's clock would start at without easing in: between the
        ramps, ``τ = tag_start + u`` (the run's clock as reports describe it)."""
        return self.on - (1.0 - self._kept) * self.ease_in

    def tag_time(self, u: ArrayLike) -> Array:
        """``τ(u)``; beyond an eased end it stays at that end, beyond the others it goes on at
        the plan's speed (a sample a hair past a run drawn at rest is the plan's own)."""
        u = np.asarray(u, dtype=float)
        tau = self.tag_start + u
        r1, r2, total = self.ease_in, self.ease_out, self.duration
        if r1 > 0.0:
            head = u < r1
            tau[head] = self.on + r1 * self._ramp(np.maximum(u[head], 0.0) / r1)[0]
        if r2 > 0.0:
            tail = u > total - r2
            tau[tail] = self.off - r2 * self._ramp(np.maximum(total - u[tail], 0.0) / r2)[0]
        return tau

    def rate(self, u: ArrayLike) -> Array:
        """``τ'(u)``: the plan's velocity times this is the run's (before the time scale)."""
        u = np.asarray(u, dtype=float)
        rate = np.ones(u.shape)
        r1, r2, total = self.ease_in, self.ease_out, self.duration
        if r1 > 0.0:
            head = u < r1
            rate[head] = self._ramp(np.maximum(u[head], 0.0) / r1)[1]
        if r2 > 0.0:
            tail = u > total - r2
            rate[tail] = self._ramp(np.maximum(total - u[tail], 0.0) / r2)[1]
        return rate


def run_clock(
    plan: Plan,
    on: float,
    off: float,
    size: float,
    jerk_limited: bool = True,
    ease_trimmed: bool = False,
) -> RunClock:
    """The clock of a run drawing ``plan`` from ``on`` to ``off`` (tag clock, within its ink
    window): easing in if it starts where the plan touches down moving, out if it ends where
    the plan lifts off moving (:data:`EASE`, at most the run's own length each), by
    smoothstep or, not ``jerk_limited``, from a constant acceleration (module docstring). With
    ``ease_trimmed``, also wherever it starts after the plan's own start or ends before its end
    (a run trimmed where little path is left: a lognormal moves everywhere between its onset and
    its end, so a trimmed end is as much a step in speed as a touch-down in motion)."""
    if off <= on or (plan.ink is None and not ease_trimmed):
        return RunClock(on, max(on, off), jerk_limited=jerk_limited)
    down, up = plan.ink_window(size)
    touches, lifts = plan.moving_ends(size) if plan.ink is not None else (False, False)
    eases = (
        (touches and on <= down + _EDGE) or (ease_trimmed and on > plan.start + _EDGE),
        (lifts and off >= up - _EDGE) or (ease_trimmed and off < plan.end(size) - _EDGE),
    )
    ramp = min(EASE, off - on)
    if all(eases):  # both ramps within the run: together they cover 2·S(1)·ramp of its clock
        ramp = min(ramp, (off - on) / (2.0 * _ramp_share(jerk_limited)))
    ease_in = ramp if eases[0] else 0.0
    ease_out = ramp if eases[1] else 0.0
    return RunClock(on, off, ease_in, ease_out, jerk_limited)
