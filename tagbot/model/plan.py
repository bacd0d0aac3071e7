"""Action plans (ΣΛ* and ΓΛ*) and tags: virtual targets, stroke parameters, and their geometry.

Conventions (fixed so that plans are portable):

- y points up; angles are radians, counter-clockwise.
- Stroke ``j`` (0-based) runs from ``targets[j]`` to ``targets[j + 1]``; its chord direction is
  ``alpha = atan2(Δy, Δx)``.
- ΓΛ*: the stroke leaves at ``alpha + phi1`` and arrives at ``alpha + phi2`` along the Euler spiral
  of :func:`~tagbot.model.euler.fit_euler`.
- ΣΛ*: the stroke is the circular arc leaving at ``alpha − phi`` and arriving at ``alpha + phi``
  (so a ΣΛ* stroke is the ΓΛ* stroke with ``phi1 = −phi``, ``phi2 = phi``; a plan stores it that
  way). Its length is ``D = c·phi / sin(phi)`` for chord ``c`` (the paper's eq. 10 prints
  ``2c·sin(phi)``, which would not reach the target; see READING-NOTES).
- ``dt[j]`` is the delay of stroke j's onset after stroke j−1's onset, and ``dt[0]`` the delay after
  the plan's ``start``: ``t0[j] = start + dt[0] + … + dt[j]``. All times are seconds on the tag's
  clock.
- The pen is on the paper for all of a plan's motion, unless the plan has an ``ink`` window
  ``(down, up)`` (seconds after ``start``): then it moves in the air before ``down`` and after
  ``up``, as a writer who touches down and lifts off while moving does (beyond the paper, which
  draws every plan from rest to rest). Only the window leaves ink.

Every stroke travels its whole curve as its lognormal CDF goes from 0 to 1, so once all strokes of
a plan are complete the pen is exactly on the last target, whatever the overlaps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.errors import PlanError
from tagbot.model import kernels
from tagbot.model.euler import Clothoids

if TYPE_CHECKING:
    from tagbot.model.motion import Motion

Model = Literal["gamma", "sigma"]
MODELS: tuple[Model, ...] = ("gamma", "sigma")

END_TOLERANCE = 1e-6
"""A plan's motion ends once the path still to travel is below this fraction of the tag's size."""

PHI_LIMIT = 3.0
"""The largest tangent deviation (rad) the fits give a stroke: away from the ±π ambiguity,
towards which a Euler spiral between two fixed targets grows without bound."""

MIN_CHORD = 1e-9
"""Consecutive targets closer than this fraction of the plan's extent are refused."""

MAX_COORDINATE = 1e15
"""Largest target coordinate magnitude (the inputs' bound too): differences stay exact enough."""
MU_RANGE = (-12.0, 6.0)
"""Log-delays accepted, log seconds: a stroke peaks between about 6 µs and 7 minutes in."""
MAX_SIGMA = 3.0
"""Largest log-response time: wider lognormals have tails of hours for any μ."""
MAX_DELAY = 3600.0
"""Longest onset delay ``dt`` and pen lift, seconds."""
MAX_DURATION = 4 * 3600.0
"""Longest tag, seconds from its first plan's start to its end (a tag is not a day's work)."""
MAX_START = 1e9
"""Largest plan start magnitude, seconds."""

DEFAULT_MU = float(np.log(0.2))
"""The paper's log-delay, shared by all strokes (§5)."""
DEFAULT_SIGMA = float(np.log(1.4))
"""The paper's log-response time, shared by all strokes (§5)."""

Array = NDArray[np.float64]


def _vector(name: str, values: ArrayLike, size: int) -> Array:
    array = np.array(values, dtype=float).reshape(-1) if np.ndim(values) else None
    if array is None or array.size != size:
        got = "a scalar" if array is None else f"{array.size} values"
        raise PlanError(f"strokes: expected {size} values of {name} (one per stroke), got {got}")
    if not np.isfinite(array).all():
        bad = int(np.flatnonzero(~np.isfinite(array))[0])
        raise PlanError(f"strokes[{bad}].{name}: must be finite, got {float(array[bad])!r}")
    return array


@dataclass(frozen=True, eq=False)
class Plan:
    """One pen-down movement (in the air before and after its ``ink`` window, if it has one):
    ``m`` virtual targets and ``m − 1`` lognormal strokes between them.

    Arrays are copied and validated on construction; a :class:`~tagbot.errors.PlanError` names the
    offending field (``strokes[2].sigma: must be > 0, got -1.0``).
    """

    targets: Array
    """Virtual targets, shape ``(m, 2)``."""
    dt: Array
    """Onset delays, seconds, shape ``(m - 1,)``; see the module docstring."""
    mu: Array
    """Log-delays (log seconds)."""
    sigma: Array
    """Log-response times (> 0)."""
    phi1: Array
    """Start-tangent deviation from the chord, radians."""
    phi2: Array
    """End-tangent deviation from the chord, radians."""
    start: float = 0.0
    """The plan's start time, seconds on the tag's clock."""
    ink: tuple[float, float] | None = None
    """When the pen touches down and lifts off, seconds after ``start``; None: the pen is down
    for the whole motion."""

    def __post_init__(self) -> None:
        targets = np.array(self.targets, dtype=float)
        if targets.ndim != 2 or targets.shape[1] != 2:
            raise PlanError(f"targets: expected a list of [x, y] pairs, got shape {targets.shape}")
        if len(targets) < 2:
            raise PlanError(f"targets: need at least 2, got {len(targets)}")
        if not np.isfinite(targets).all():
            bad = int(np.flatnonzero(~np.all(np.isfinite(targets), axis=1))[0])
            raise PlanError(f"targets[{bad}]: must be finite, got {targets[bad].tolist()}")
        if np.abs(targets).max() > MAX_COORDINATE:
            bad = int(np.flatnonzero(np.abs(targets).max(axis=1) > MAX_COORDINATE)[0])
            raise PlanError(
                f"targets[{bad}]: beyond ±{MAX_COORDINATE:g}, got {targets[bad].tolist()}"
            )
        step = np.diff(targets, axis=0)
        chord = np.hypot(step[:, 0], step[:, 1])
        extent = float(np.hypot(*np.ptp(targets, axis=0)))
        if chord.min() < max(MIN_CHORD * extent, 1e-100):
            same = np.flatnonzero(chord == 0.0)
            if same.size:
                raise PlanError(f"targets[{same[0] + 1}]: coincides with targets[{same[0]}]")
            j = int(np.flatnonzero(chord < max(MIN_CHORD * extent, 1e-100))[0])
            raise PlanError(
                f"targets[{j + 1}]: too close to targets[{j}] ({chord[j]:.3g} apart in a plan"
                f" {extent:.3g} across; need more than {MIN_CHORD:g} of it)"
            )
        n = len(targets) - 1
        fields = {name: _vector(name, getattr(self, name), n) for name in _STROKE_FIELDS}
        if fields["dt"].min() < 0:
            j = int(np.flatnonzero(fields["dt"] < 0)[0])
            raise PlanError(f"strokes[{j}].dt: must be >= 0, got {float(fields['dt'][j])!r}")
        if fields["dt"].max() > MAX_DELAY:
            j = int(np.flatnonzero(fields["dt"] > MAX_DELAY)[0])
            raise PlanError(
                f"strokes[{j}].dt: must be <= {MAX_DELAY:g} s, got {float(fields['dt'][j])!r}"
            )
        if fields["sigma"].min() <= 0:
            j = int(np.flatnonzero(fields["sigma"] <= 0)[0])
            raise PlanError(f"strokes[{j}].sigma: must be > 0, got {float(fields['sigma'][j])!r}")
        if fields["sigma"].max() > MAX_SIGMA:
            j = int(np.flatnonzero(fields["sigma"] > MAX_SIGMA)[0])
            raise PlanError(
                f"strokes[{j}].sigma: must be <= {MAX_SIGMA:g}, got {float(fields['sigma'][j])!r}"
            )
        lo, hi = MU_RANGE
        outside = np.flatnonzero((fields["mu"] < lo) | (fields["mu"] > hi))
        if outside.size:
            j = int(outside[0])
            raise PlanError(
                f"strokes[{j}].mu: must be in [{lo:g}, {hi:g}], got {float(fields['mu'][j])!r}"
            )
        start = float(self.start)
        if not (np.isfinite(start) and abs(start) <= MAX_START):
            raise PlanError(
                f"start: must be finite and within ±{MAX_START:g} s, got {self.start!r}"
            )
        targets.flags.writeable = False
        object.__setattr__(self, "targets", targets)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "ink", _ink(self.ink))
        for name, array in fields.items():
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    @classmethod
    def sigma_model(
        cls,
        targets: ArrayLike,
        dt: ArrayLike,
        mu: ArrayLike,
        sigma: ArrayLike,
        phi: ArrayLike,
        start: float = 0.0,
        ink: tuple[float, float] | None = None,
    ) -> Plan:
        """A ΣΛ* plan: circular-arc strokes deviating ``phi`` from the chord (|phi| < π)."""
        phi = np.asarray(phi, dtype=float)
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~(np.abs(phi.reshape(-1)) < np.pi))
        if bad.size:
            j = int(bad[0])
            got = phi.reshape(-1)[j]
            raise PlanError(
                f"strokes[{j}].phi: must be finite and in (-pi, pi), got {float(got)!r}"
            )
        return cls(targets, dt, mu, sigma, -phi, phi, start, ink)

    @property
    def phi(self) -> Array:
        """The ΣΛ* deviation ``phi`` (= ``phi2``; meaningful when ``phi1 == -phi2``)."""
        return self.phi2

    def at(self, start: float) -> Plan:
        """The same plan starting at ``start`` (its fitted geometry is reused)."""
        moved = Plan(
            self.targets, self.dt, self.mu, self.sigma, self.phi1, self.phi2, start, self.ink
        )
        if "geometry" in self.__dict__:
            moved.__dict__["geometry"] = self.geometry
        return moved

    @cached_property
    def arcs(self) -> NDArray[np.bool_]:
        """Which strokes are circular arcs (ΣΛ* strokes): ``phi1 == -phi2`` with ``|phi2| < π``."""
        return _arcs(self.phi1, self.phi2)

    @property
    def n_strokes(self) -> int:
        return len(self.dt)

    @cached_property
    def onsets(self) -> Array:
        """Stroke onsets ``t0``, seconds on the tag's clock."""
        return self.start + np.cumsum(self.dt)

    @cached_property
    def chords(self) -> Array:
        """Chord vectors ``targets[j + 1] − targets[j]``, shape ``(m − 1, 2)``."""
        return np.diff(self.targets, axis=0)

    @cached_property
    def geometry(self) -> Clothoids:
        """Each stroke's curve as a clothoid segment (arcs for ΣΛ* strokes)."""
        return place_strokes(unit_strokes(self.phi1, self.phi2), self.targets)

    def windows(self, size: float, tol: float = END_TOLERANCE) -> tuple[Array, Array]:
        """Each stroke's active window ``(t_on, t_off)``.

        Outside it a stroke counts as not started (0) or complete (its whole chord), which moves
        the pen by at most ``tol × size`` in total: each of the ``n`` strokes of length ``D`` gets
        the budget ``eps = tol·size / (n·D)`` on either side.
        """
        budget = tol * size / (self.n_strokes * self.geometry.length)
        return stroke_windows(self.onsets, self.mu, self.sigma, budget)

    def end(self, size: float, tol: float = END_TOLERANCE) -> float:
        """When the plan's motion ends: the path left to travel is below ``tol × size``."""
        return float(np.max(self.windows(size, tol)[1]))

    def ink_window(self, size: float) -> tuple[float, float]:
        """When the pen is down, ``(touch-down, lift-off)`` on the tag's clock: the ``ink``
        window within the motion, or the whole motion ``(start, end)``."""
        end = self.end(size)
        if self.ink is None:
            return self.start, end
        return self.start + self.ink[0], min(self.start + self.ink[1], end)

    def moving_ends(self, size: float) -> tuple[bool, bool]:
        """Whether the pen touches down after the motion starts, and lifts off before it ends
        (an ``ink`` window inside the motion)."""
        if self.ink is None:
            return False, False
        return self.ink[0] > 0.0, self.ink_window(size)[1] < self.end(size)


_STROKE_FIELDS = ("dt", "mu", "sigma", "phi1", "phi2")


def _ink(value: object) -> tuple[float, float] | None:
    """A checked ``ink`` window: two finite times ``0 <= down < up <= MAX_DURATION``."""
    if value is None:
        return None
    try:
        down, up = (float(x) for x in value)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise PlanError(f"ink: expected [down, up] seconds after start, got {value!r}") from None
    if not (np.isfinite(down) and np.isfinite(up) and 0.0 <= down < up <= MAX_DURATION):
        raise PlanError(
            f"ink: need 0 <= down < up <= {MAX_DURATION:g} s after start, got [{down!r}, {up!r}]"
        )
    return down, up


def unit_strokes(phi1: ArrayLike, phi2: ArrayLike) -> Clothoids:
    """Each stroke's shape on the unit chord ``(0, 0) → (1, 0)``: all that ``phi1, phi2`` set.

    A stroke's curve is its shape scaled by the chord's length and turned to its direction
    (:func:`place_strokes`). ΣΛ* strokes (``phi1 == -phi2``, ``|phi2| < π``) are circular arcs in
    closed form, exact where the spiral fit's root would be ~1e-17 rather than 0; the others are
    :func:`~tagbot.model.euler.fit_euler`'s G1 spirals.
    """
    phi1, phi2 = np.broadcast_arrays(np.asarray(phi1, dtype=float), np.asarray(phi2, dtype=float))
    flat1, flat2 = np.ascontiguousarray(phi1.ravel()), np.ascontiguousarray(phi2.ravel())
    theta0, kappa0, dkappa, length = kernels.unit_strokes_array(flat1, flat2).T.reshape(
        (4, *phi1.shape)
    )
    zeros = np.zeros(phi1.shape)
    return Clothoids(zeros, zeros.copy(), theta0, kappa0, dkappa, length)


def _arcs(phi1: Array, phi2: Array) -> NDArray[np.bool_]:
    """Which strokes are ΣΛ* arcs (:func:`~tagbot.model.kernels.is_arc`)."""
    phi1, phi2 = np.broadcast_arrays(np.asarray(phi1, dtype=float), np.asarray(phi2, dtype=float))
    flat1, flat2 = np.ascontiguousarray(phi1.ravel()), np.ascontiguousarray(phi2.ravel())
    return kernels.arcs_array(flat1, flat2).reshape(phi1.shape)


def place_strokes(shapes: Clothoids, targets: Array) -> Clothoids:
    """Unit-chord ``shapes`` (:func:`unit_strokes`) stretched between consecutive ``targets``."""
    chord = np.diff(targets, axis=0)
    c = np.hypot(chord[:, 0], chord[:, 1])
    return Clothoids(
        x0=targets[:-1, 0].copy(),
        y0=targets[:-1, 1].copy(),
        theta0=np.arctan2(chord[:, 1], chord[:, 0]) + shapes.theta0,
        kappa0=shapes.kappa0 / c,
        dkappa=shapes.dkappa / (c * c),
        length=shapes.length * c,
    )


def stroke_windows(
    onsets: Array, mu: Array, sigma: Array, budget: ArrayLike
) -> tuple[Array, Array]:
    """Active windows ``(t_on, t_off)`` of lognormal strokes outside which each is within
    ``budget`` (a fraction of its length, capped at 1 %) of not started or of complete."""
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (onsets, mu, sigma, budget)))
    flat = [np.ascontiguousarray(a.ravel()) for a in arrays]
    t_on, t_off = kernels.windows_array(*flat)
    return t_on.reshape(arrays[0].shape), t_off.reshape(arrays[0].shape)


@dataclass(frozen=True, eq=False)
class Tag:
    """An ordered sequence of plans with pen lifts between them.

    Plans are drawn one after another: each touches down once the previous one has lifted the
    pen (:meth:`Plan.ink_window`). Their motions in the air may overlap: a lognormal tail after
    a lift-off is cut where the next plan takes over (:func:`~tagbot.model.motion.sample`),
    never drawn as ink that delays the next plan.
    """

    plans: tuple[Plan, ...]
    model: Model = "gamma"
    units: str = "mm"

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise PlanError(f"model: must be 'gamma' or 'sigma', got {self.model!r}")
        plans = tuple(self.plans)
        if not plans:
            raise PlanError("plans: empty (a tag needs at least one plan)")
        for k, plan in enumerate(plans):
            if not isinstance(plan, Plan):
                raise PlanError(f"plans[{k}]: expected a Plan, got {type(plan).__name__}")
            if self.model == "sigma" and not np.all(plan.arcs):
                j = int(np.flatnonzero(~plan.arcs)[0])
                raise PlanError(
                    f"plans[{k}].strokes[{j}].phi: a sigma-model stroke is an arc with"
                    f" phi1 == -phi2 and |phi| < pi, got phi1={float(plan.phi1[j])!r},"
                    f" phi2={float(plan.phi2[j])!r}"
                )
        object.__setattr__(self, "plans", plans)
        for k, plan in enumerate(plans):
            if plan.ink is not None and plan.start + plan.ink[0] >= plan.end(self.size):
                raise PlanError(
                    f"plans[{k}].ink: the pen touches down {plan.ink[0]:.6g} s after the start,"
                    f" once the motion has ended ({plan.end(self.size) - plan.start:.6g} s)"
                )
        if plans[-1].end(self.size) - plans[0].start > MAX_DURATION:
            raise PlanError(
                f"plans: the tag lasts {plans[-1].end(self.size) - plans[0].start:.6g} s, more"
                f" than {MAX_DURATION:g} s"
            )
        for k in range(1, len(plans)):
            lift_off = plans[k - 1].ink_window(self.size)[1]
            touch_down = plans[k].ink_window(self.size)[0]
            if touch_down < lift_off:
                raise PlanError(
                    f"plans[{k}]: the pen touches down at {touch_down:.6g} s, before plans[{k - 1}]"
                    f" lifts it off ({lift_off:.6g} s); plans are drawn one after another"
                )

    @cached_property
    def size(self) -> float:
        """The diagonal of the targets' bounding box: the tag's length scale."""
        points = np.concatenate([plan.targets for plan in self.plans])
        return float(np.hypot(*(points.max(axis=0) - points.min(axis=0))))

    @property
    def start(self) -> float:
        """When the first plan starts."""
        return self.plans[0].start

    @cached_property
    def end(self) -> float:
        """When the last plan's motion ends."""
        return self.plans[-1].end(self.size)

    @property
    def n_strokes(self) -> int:
        return sum(plan.n_strokes for plan in self.plans)

    def sample(self, dt: float = 0.01) -> Motion:
        """The motion at a fixed time step ``dt`` in seconds; see :func:`.motion.sample`."""
        from tagbot.model.motion import sample

        return sample(self, dt)


def sequence(
    plans: Sequence[Plan],
    lifts: float | Sequence[float],
    model: Model = "gamma",
    units: str = "mm",
) -> Tag:
    """A tag drawing ``plans`` in order, each starting ``lifts[k]`` seconds after plan ``k`` ends.

    The first plan keeps its start. ``lifts`` is one duration for all, or one per pen lift.
    """
    plans = list(plans)
    if not plans:
        raise PlanError("plans: empty (a tag needs at least one plan)")
    gaps = np.broadcast_to(np.asarray(lifts, dtype=float), (max(len(plans) - 1, 0),))
    if np.any(~np.isfinite(gaps)) or np.any(gaps < 0):
        raise PlanError(f"lifts: must be finite and >= 0, got {gaps.tolist()}")
    points = np.concatenate([plan.targets for plan in plans])
    size = float(np.hypot(*np.ptp(points, axis=0)))
    timed = [plans[0]]
    for plan, gap in zip(plans[1:], gaps, strict=True):
        timed.append(plan.at(timed[-1].end(size) + float(gap)))
    return Tag(tuple(timed), model, units)


def random_plan(
    rng: np.random.Generator,
    targets: tuple[int, int] = (3, 8),
    step: tuple[float, float] = (20.0, 50.0),
    turn: float = 2.5,
    phi: float = 1.2,
    dt: tuple[float, float] = (0.1, 0.35),
    sigma_model: bool = False,
) -> Plan:
    """A random plausible plan: a walk of ``targets`` (inclusive range) targets ``step`` mm apart
    turning up to ``±turn`` rad each time, tangent deviations within ``±phi``, delays in ``dt``
    (the first 0), the paper's mu and sigma. Synthetic data for tests, benchmarks and demos."""
    m = int(rng.integers(targets[0], targets[1] + 1))
    heading = np.cumsum(rng.uniform(-turn, turn, m))
    length = rng.uniform(step[0], step[1], m)
    points = np.cumsum(
        np.column_stack([length * np.cos(heading), length * np.sin(heading)]), axis=0
    )
    n = m - 1
    delays = np.r_[0.0, rng.uniform(dt[0], dt[1], n - 1)]
    mu, sigma = np.full(n, DEFAULT_MU), np.full(n, DEFAULT_SIGMA)
    if sigma_model:
        return Plan.sigma_model(points, delays, mu, sigma, rng.uniform(-phi, phi, n))
    return Plan(points, delays, mu, sigma, rng.uniform(-phi, phi, n), rng.uniform(-phi, phi, n))


def random_timed_plan(rng: np.random.Generator) -> Plan:
    """:func:`random_plan`'s shape with random per-stroke timing, as a recorded hand has: onsets
    0.08-0.3 s apart, median delays ``exp(mu)`` of 0.12-0.35 s, sigma 0.15-0.45. Synthetic data
    for the timing-aware fit's tests and benchmarks."""
    p = random_plan(rng)
    n = p.n_strokes
    dt = np.r_[0.0, rng.uniform(0.08, 0.3, n - 1)]
    mu = rng.uniform(np.log(0.12), np.log(0.35), n)
    sigma = rng.uniform(0.15, 0.45, n)
    return Plan(p.targets, dt, mu, sigma, p.phi1, p.phi2)
