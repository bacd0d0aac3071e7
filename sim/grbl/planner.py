"""Grbl 1.1's look-ahead motion planner, in simulated form.

The planner receives already-parsed motion blocks (:class:`MotionBlock`, :class:`Dwell`) and
keeps at most 15 of them (``BLOCK_BUFFER_SIZE`` 16, one slot always empty), as Grbl 1.1h's
``planner.c`` does. This module is an independent Python rendering of that algorithm, written
from its documented behaviour; the stepper side (segment generation and time) is in
:mod:`sim.grbl.executor`.

What a block gets when it is buffered (``plan_buffer_line``):

- Targets are rounded to whole steps (``lround(target * steps_per_mm)``, halves away from zero);
  the block's length and unit vector come from the *step* deltas, so a block that rounds to no
  step at all is dropped (Grbl still acknowledges it with ``ok``).
- Acceleration and maximum rate are limited per axis along the unit vector:
  ``min over moving axes of limit[i] / |u[i]|`` ($120–$122, $110–$112).
- Nominal speed: a rapid (G0) runs at that maximum rate; a feed move at F mm/min (G94) or, with
  inverse time (G93), at ``F * length`` mm/min so that it lasts 1/F minutes; both capped at the
  maximum rate and never below 1 mm/min (``MINIMUM_FEED_RATE``).
- Junction speed with the previous block, from the junction deviation δ ($11) and the angle θ
  between the two directions: ``v² = a_j · δ · sin(θ/2) / (1 − sin(θ/2))``, where
  ``cos θ = −u_prev · u`` and ``a_j`` is the acceleration limit along ``u − u_prev``. A straight
  continuation has no junction limit; a full reversal stops. A block queued into an *empty*
  planner starts from rest, whatever the machine is doing: this is how starvation turns into
  stops.
- The maximum entry speed is the smallest of the junction speed and the nominal speeds of the
  block and of the one before it.

Then ``planner_recalculate``: a reverse pass from the newest block (planned to end at rest) back
to the last optimally planned block, giving each block the entry speed from which it can still
decelerate over its own length to its successor's entry, and a forward pass that lowers entry
speeds the previous block cannot reach by accelerating. Because the newest block must end at
rest, a stream of short segments is capped by what the queued distance allows:
``v ≤ √(2·a·ΣL)``, about ``√(2·a·15·L)`` for 15 blocks of length ``L``. The "planned" pointer
marks where nothing before can improve any more, so each new block costs only the blocks after
it, as in Grbl.

Speeds are kept in mm/s and accelerations in mm/s² (Grbl uses mm/min and mm/min²; the arithmetic
is the same up to rounding).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

BLOCK_BUFFER_SIZE = 16
"""Grbl's planner ring buffer; one slot is always left empty, so 15 blocks are usable.
A build with ``USE_LINE_NUMBERS`` has 15 (14 usable)."""

PLANNER_CAPACITY = BLOCK_BUFFER_SIZE - 1
"""Blocks the planner can hold at once (what ``Bf:`` reports as available when empty)."""

MINIMUM_FEED_RATE_MM_PER_MIN = 1.0
"""Grbl's floor on any nominal speed (config.h), to avoid step-rate round-off."""

MINIMUM_JUNCTION_SPEED = 0.0
"""Grbl's floor on junction speeds (config.h)."""

DWELL_TIME_STEP = 0.050
"""``delay_sec``'s step (``DWELL_TIME_STEP``, 50 ms): a dwell lasts a whole number of them."""

_LARGE = 1.0e38  # Grbl's SOME_LARGE_VALUE: "no limit".


def _positive_triple(name: str, values: tuple[float, float, float]) -> tuple[float, float, float]:
    try:
        triple = tuple(float(v) for v in values)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected three numbers, got {values!r}") from exc
    if len(triple) != 3 or not all(math.isfinite(v) and v > 0 for v in triple):
        raise ValueError(f"{name}: expected three finite numbers > 0, got {values!r}")
    return triple  # type: ignore[return-value]


@dataclass(frozen=True)
class GrblSettings:
    """The machine settings the planner and stepper use.

    Defaults are Grbl 1.1h's generic defaults (``defaults_generic.h``): 250 steps/mm, 500 mm/min,
    10 mm/s², junction deviation 0.010 mm, step idle delay 25 ms.
    """

    steps_per_mm: tuple[float, float, float] = (250.0, 250.0, 250.0)  # $100, $101, $102
    max_rate_mm_per_min: tuple[float, float, float] = (500.0, 500.0, 500.0)  # $110, $111, $112
    acceleration_mm_per_s2: tuple[float, float, float] = (10.0, 10.0, 10.0)  # $120, $121, $122
    junction_deviation_mm: float = 0.010  # $11
    stepper_idle_lock_ms: int = 25  # $1 (255: keep the motors enabled, no delay)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "steps_per_mm", _positive_triple("steps_per_mm", self.steps_per_mm)
        )
        object.__setattr__(
            self,
            "max_rate_mm_per_min",
            _positive_triple("max_rate_mm_per_min", self.max_rate_mm_per_min),
        )
        object.__setattr__(
            self,
            "acceleration_mm_per_s2",
            _positive_triple("acceleration_mm_per_s2", self.acceleration_mm_per_s2),
        )
        jd = self.junction_deviation_mm
        if isinstance(jd, bool) or not isinstance(jd, (int, float)) or not math.isfinite(jd):
            raise ValueError(f"junction_deviation_mm: expected a finite number, got {jd!r}")
        if jd < 0:
            raise ValueError(f"junction_deviation_mm: must be >= 0, got {jd!r}")
        object.__setattr__(self, "junction_deviation_mm", float(jd))
        lock = self.stepper_idle_lock_ms
        if isinstance(lock, bool) or not isinstance(lock, (int, float)) or lock != int(lock):
            raise ValueError(f"stepper_idle_lock_ms: expected an integer, got {lock!r}")
        if not 0 <= lock <= 255:
            raise ValueError(f"stepper_idle_lock_ms: must be in 0..255, got {lock!r}")
        object.__setattr__(self, "stepper_idle_lock_ms", int(lock))

    @property
    def idle_lock_delay_s(self) -> float:
        """How long the step interrupt holds the motors after the last step before the cycle
        stops (``st_go_idle``'s ``delay_ms($1)``); 255 keeps them enabled with no delay."""
        lock = self.stepper_idle_lock_ms
        return 0.0 if lock == 255 else lock / 1000.0

    @classmethod
    def from_dollar_settings(cls, values: Mapping[int | str, float]) -> GrblSettings:
        """Settings from Grbl ``$N=value`` pairs, e.g. ``{100: 80, "$110": 6000, 11: 0.01}``.

        Only $1, $11, $100–$102, $110–$112 and $120–$122 matter here; others are ignored, and
        missing ones keep their defaults.
        """
        by_number: dict[int, float] = {}
        for key, value in values.items():
            number = int(str(key).lstrip("$"))
            by_number[number] = float(value)
        base = cls()

        def triple(first: int, default: tuple[float, float, float]) -> tuple[float, float, float]:
            return tuple(by_number.get(first + i, default[i]) for i in range(3))  # type: ignore[return-value]

        return cls(
            steps_per_mm=triple(100, base.steps_per_mm),
            max_rate_mm_per_min=triple(110, base.max_rate_mm_per_min),
            acceleration_mm_per_s2=triple(120, base.acceleration_mm_per_s2),
            junction_deviation_mm=by_number.get(11, base.junction_deviation_mm),
            stepper_idle_lock_ms=int(by_number.get(1, base.stepper_idle_lock_ms)),
        )


@dataclass(frozen=True)
class MotionBlock:
    """One straight move to an absolute machine position, as the G-code parser hands it over.

    Exactly one way of giving the speed: ``rapid=True`` (G0, at the maximum rates),
    ``feed_mm_per_min`` (G1 under G94) or ``inverse_time_per_min`` (G1 under G93: the F word,
    in 1/min, so that the block lasts 1/F minutes). ``line_number`` is the line's N word
    (``Ln:``), ``tag`` anything the caller wants back from the planner block (not compared).
    """

    target_mm: tuple[float, float, float]
    feed_mm_per_min: float | None = None
    inverse_time_per_min: float | None = None
    rapid: bool = False
    line_number: int = field(default=0, compare=False)
    tag: object = field(default=None, compare=False)

    def __post_init__(self) -> None:
        try:
            target = tuple(float(v) for v in self.target_mm)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"target_mm: expected three numbers, got {self.target_mm!r}") from exc
        if len(target) != 3 or not all(math.isfinite(v) for v in target):
            raise ValueError(f"target_mm: expected three finite numbers, got {self.target_mm!r}")
        object.__setattr__(self, "target_mm", target)
        given = [
            name
            for name, value in (
                ("feed_mm_per_min", self.feed_mm_per_min),
                ("inverse_time_per_min", self.inverse_time_per_min),
            )
            if value is not None
        ]
        if self.rapid:
            if given:
                raise ValueError(f"{given[0]}: a rapid move takes no feed rate")
            return
        if len(given) != 1:
            raise ValueError(
                "feed_mm_per_min / inverse_time_per_min: give exactly one for a feed move"
            )
        value = getattr(self, given[0])
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{given[0]}: expected a number, got {value!r}")
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{given[0]}: must be a finite number > 0, got {value!r}")
        object.__setattr__(self, given[0], float(value))


@dataclass(frozen=True)
class Dwell:
    """G4: wait for every queued move to finish, then pause before the next line.

    ``seconds`` is the P word; the pause is :attr:`duration`: Grbl's ``delay_sec`` waits
    ``ceil(20·P)`` steps of :data:`DWELL_TIME_STEP` (50 ms), computed in 32-bit floats.
    """

    seconds: float

    def __post_init__(self) -> None:
        s = self.seconds
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s) or s < 0:
            raise ValueError(f"seconds: must be a finite number >= 0, got {s!r}")
        object.__setattr__(self, "seconds", float(s))

    @property
    def ticks(self) -> int:
        """``delay_sec``'s loop count: ``ceil(1000 / DWELL_TIME_STEP · P)`` in float32."""
        return math.ceil(float(np.float32(self.seconds) * np.float32(20.0)))

    @property
    def duration(self) -> float:
        """The pause Grbl makes, seconds: :attr:`ticks` × 50 ms."""
        return self.ticks * DWELL_TIME_STEP


def lround(x: float) -> int:
    """C's lround: nearest integer, halves away from zero (Python's round() goes to even)."""
    return math.floor(abs(x) + 0.5) * (1 if x >= 0 else -1)


def limit_by_axis_maximum(limits: tuple[float, float, float], unit: tuple[float, ...]) -> float:
    """Largest value along ``unit`` that keeps every axis component within its own limit."""
    value = _LARGE
    for limit, u in zip(limits, unit, strict=True):
        if u != 0.0:
            value = min(value, limit / abs(u))
    return value


@dataclass(eq=False)
class PlanBlock:
    """A block in the planner buffer (Grbl's ``plan_block_t``), speeds in mm/s.

    ``millimeters`` is the distance still to be prepared by the stepper: it shrinks as segments
    are generated, as in Grbl. ``length_mm`` keeps the original length.
    """

    source: MotionBlock
    start_steps: tuple[int, int, int]
    target_steps: tuple[int, int, int]
    steps: tuple[int, int, int]  # absolute step counts per axis
    directions: tuple[int, int, int]  # +1 / -1 per axis
    step_event_count: int
    length_mm: float
    millimeters: float
    unit_vec: tuple[float, float, float]
    acceleration: float  # mm/s²
    rapid_rate: float  # mm/s
    nominal_speed: float  # mm/s
    max_junction_speed_sqr: float = 0.0
    max_entry_speed_sqr: float = 0.0
    entry_speed_sqr: float = 0.0

    def steps_after(self, events: int) -> tuple[int, int, int]:
        """Absolute axis positions (steps) after ``events`` of this block's step events.

        Grbl's Bresenham counters start at half the event count (with the AMASS ×8 scaling)
        and step when they exceed it, so axis *i* has made ``⌊(4N + 8·k·s_i − 1) / 8N⌋`` steps
        after *k* events.
        """
        n = self.step_event_count
        if events >= n:
            return self.target_steps
        if events <= 0:
            return self.start_steps
        half, full = 4 * n, 8 * n
        return tuple(
            start + d * ((half + 8 * events * s - 1) // full)
            for start, d, s in zip(self.start_steps, self.directions, self.steps, strict=True)
        )  # type: ignore[return-value]


class GrblPlanner:
    """Grbl 1.1's planner buffer: ``plan_buffer_line``, ``planner_recalculate`` and friends.

    ``blocks[0]`` is the buffer tail (the block the stepper is preparing, or the next one); the
    list never holds more than ``capacity`` (:data:`PLANNER_CAPACITY`) blocks.
    ``on_tail_replanned`` is called whenever the reverse pass reaches the tail block (Grbl's
    ``st_update_plan_block_parameters``), so that the stepper can recompute the partially
    prepared block's profile.
    """

    def __init__(
        self,
        settings: GrblSettings,
        position_steps: tuple[int, int, int] = (0, 0, 0),
        on_tail_replanned: Callable[[], None] | None = None,
        capacity: int = PLANNER_CAPACITY,
    ) -> None:
        self.settings = settings
        self.capacity = int(capacity)
        self.blocks: list[PlanBlock] = []
        self.planned = 0  # index of the first block after the optimally planned ones
        self.position_steps = tuple(int(v) for v in position_steps)
        self.previous_unit_vec: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.previous_nominal_speed = 0.0
        self.on_tail_replanned = on_tail_replanned
        self._accel = settings.acceleration_mm_per_s2
        self._rates = tuple(r / 60.0 for r in settings.max_rate_mm_per_min)

    # -- buffer state ----------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self.blocks)

    @property
    def full(self) -> bool:
        """True when ``plan_check_full_buffer`` would block the parser."""
        return len(self.blocks) >= self.capacity

    @property
    def free_blocks(self) -> int:
        """``plan_get_block_buffer_available``: what Grbl reports as ``Bf:<blocks>,…``."""
        return self.capacity - len(self.blocks)

    def current_block(self) -> PlanBlock | None:
        return self.blocks[0] if self.blocks else None

    def exit_speed_sqr_of_current(self) -> float:
        """``plan_get_exec_block_exit_speed_sqr``: the entry speed² of the block after the tail."""
        return self.blocks[1].entry_speed_sqr if len(self.blocks) > 1 else 0.0

    def discard_current_block(self) -> None:
        if self.blocks:
            self.blocks.pop(0)
            # Push the planned pointer along if it pointed at the discarded tail.
            self.planned = max(self.planned - 1, 0)

    def reset(self, position_steps: tuple[int, int, int]) -> None:
        """``plan_reset`` + ``plan_sync_position``: empty buffer, forget the previous block."""
        self.blocks.clear()
        self.planned = 0
        self.previous_unit_vec = (0.0, 0.0, 0.0)
        self.previous_nominal_speed = 0.0
        self.position_steps = tuple(int(v) for v in position_steps)

    def cycle_reinitialize(self) -> None:
        """``plan_cycle_reinitialize`` after a feed hold: re-plan everything from rest."""
        if self.on_tail_replanned is not None:
            self.on_tail_replanned()
        self.planned = 0
        self.recalculate()

    # -- buffering ---------------------------------------------------------------------------

    def buffer_line(self, block: MotionBlock) -> PlanBlock | None:
        """``plan_buffer_line``. The caller checks :attr:`full` first, as ``mc_line`` does.

        Returns the new planner block, or None for a block that moves no step (dropped).
        """
        if self.full:
            raise RuntimeError("planner buffer full")
        spm = self.settings.steps_per_mm
        start = self.position_steps
        target = tuple(lround(t * s) for t, s in zip(block.target_mm, spm, strict=True))
        deltas = [t - p for t, p in zip(target, start, strict=True)]
        steps = tuple(abs(d) for d in deltas)
        step_event_count = max(steps)
        if step_event_count == 0:
            return None
        delta_mm = [d / s for d, s in zip(deltas, spm, strict=True)]
        length = math.sqrt(sum(d * d for d in delta_mm))
        unit = tuple(d / length for d in delta_mm)
        acceleration = limit_by_axis_maximum(self._accel, unit)
        rapid_rate = limit_by_axis_maximum(self._rates, unit)
        if block.rapid:
            programmed = rapid_rate
        elif block.inverse_time_per_min is not None:
            programmed = block.inverse_time_per_min * length / 60.0
        else:
            programmed = block.feed_mm_per_min / 60.0  # type: ignore[operator]
        # plan_compute_profile_nominal_speed (overrides at 100 %).
        nominal = programmed if block.rapid else min(programmed, rapid_rate)
        nominal = max(nominal, MINIMUM_FEED_RATE_MM_PER_MIN / 60.0)

        pb = PlanBlock(
            source=block,
            start_steps=start,  # type: ignore[arg-type]
            target_steps=target,  # type: ignore[arg-type]
            steps=steps,  # type: ignore[arg-type]
            directions=tuple(-1 if d < 0 else 1 for d in deltas),  # type: ignore[arg-type]
            step_event_count=step_event_count,
            length_mm=length,
            millimeters=length,
            unit_vec=unit,  # type: ignore[arg-type]
            acceleration=acceleration,
            rapid_rate=rapid_rate,
            nominal_speed=nominal,
        )

        if not self.blocks:
            # Starting from rest: the planner cannot know the machine is still moving.
            pb.entry_speed_sqr = 0.0
            pb.max_junction_speed_sqr = 0.0
        else:
            prev = self.previous_unit_vec
            cos_theta = -sum(p * u for p, u in zip(prev, unit, strict=True))
            if cos_theta > 0.999999:
                # A (near) full reversal: stop at the junction.
                pb.max_junction_speed_sqr = MINIMUM_JUNCTION_SPEED**2
            elif cos_theta < -0.999999:
                # Straight on: no junction limit.
                pb.max_junction_speed_sqr = _LARGE
            else:
                junction = [u - p for u, p in zip(unit, prev, strict=True)]
                norm = math.sqrt(sum(j * j for j in junction))
                junction_accel = limit_by_axis_maximum(self._accel, [j / norm for j in junction])
                sin_theta_d2 = math.sqrt(0.5 * (1.0 - cos_theta))
                pb.max_junction_speed_sqr = max(
                    MINIMUM_JUNCTION_SPEED**2,
                    junction_accel
                    * self.settings.junction_deviation_mm
                    * sin_theta_d2
                    / (1.0 - sin_theta_d2),
                )

        # plan_compute_profile_parameters
        prev_nominal = self.previous_nominal_speed
        limit = prev_nominal if nominal > prev_nominal else nominal
        pb.max_entry_speed_sqr = min(limit * limit, pb.max_junction_speed_sqr)
        self.previous_nominal_speed = nominal
        self.previous_unit_vec = unit  # type: ignore[assignment]
        self.position_steps = target

        self.blocks.append(pb)
        self.recalculate()
        return pb

    def recalculate(self) -> None:
        """``planner_recalculate``: reverse then forward pass over the not-yet-optimal blocks."""
        blocks = self.blocks
        last = len(blocks) - 1
        planned = self.planned
        if last < 0 or last == planned:
            return
        current = blocks[last]
        current.entry_speed_sqr = min(
            current.max_entry_speed_sqr, 2.0 * current.acceleration * current.millimeters
        )
        index = last - 1
        if index == planned:
            if index == 0 and self.on_tail_replanned is not None:
                self.on_tail_replanned()
        else:
            while index != planned:
                nxt = current
                current = blocks[index]
                index -= 1
                if index == 0 and self.on_tail_replanned is not None:
                    self.on_tail_replanned()
                if current.entry_speed_sqr != current.max_entry_speed_sqr:
                    entry = nxt.entry_speed_sqr + 2.0 * current.acceleration * current.millimeters
                    current.entry_speed_sqr = min(entry, current.max_entry_speed_sqr)

        # Forward pass from the planned pointer; move the pointer past optimal blocks.
        nxt = blocks[planned]
        for index in range(planned + 1, last + 1):
            current = nxt
            nxt = blocks[index]
            if current.entry_speed_sqr < nxt.entry_speed_sqr:
                entry = current.entry_speed_sqr + 2.0 * current.acceleration * current.millimeters
                if entry < nxt.entry_speed_sqr:
                    nxt.entry_speed_sqr = entry
                    planned = index
            if nxt.entry_speed_sqr == nxt.max_entry_speed_sqr:
                planned = index
        self.planned = planned
