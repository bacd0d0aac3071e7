"""Grbl 1.1's stepper side in simulated time: segment preparation, execution, hold and reset.

:class:`GrblExecutor` owns a :class:`~sim.grbl.planner.GrblPlanner` and runs it against a
simulated clock, reproducing ``stepper.c``'s timing:

- **Segments.** The main loop keeps a segment buffer topped up (``SEGMENT_BUFFER_SIZE`` 6, so
  at most 5 segments, the executing one included). Each segment is prepared from the tail planner
  block's trapezoid/triangle velocity profile (entry speed, nominal speed, exit speed = next
  block's entry, acceleration ramps), covering ``DT_SEGMENT`` = 1/100 s
  (``ACCELERATION_TICKS_PER_SECOND``), or less where the block ends, or more when a slow segment
  would hold less than 1.25 steps. A segment executes its whole steps at one constant rate (the
  average speed over the segment); the fraction of a step left over is carried into the next
  segment's timing, so that block times come out exact. Step periods are rounded up to 16 MHz
  CPU cycles and truncated as the AMASS timer levels do.
- **Freeing planner slots.** A planner block is discarded when its *last segment is prepared*,
  not when it has been executed: the parser may then queue another block (and Grbl sends its
  ``ok``) while up to five segments of the old one are still to run.
- **Re-planning on the fly.** When a new block changes the exit speed of the block being
  prepared, that block's remaining profile is recomputed from the speed the last prepared segment
  ends at (``st_update_plan_block_parameters``); already prepared segments are not changed.
- **Starting and stopping.** Grbl starts a cycle only when its parser runs out of input, when
  the planner is full, or when a command must wait for motion (G4); see
  :meth:`GrblExecutor.cycle_start`. When the segment buffer runs dry the step interrupt holds
  the motors for the step idle delay ($1, 25 ms by default) before the cycle stops: Grbl still
  reports ``Run`` meanwhile and its main loop reads nothing (:attr:`GrblExecutor.locked`).
- **Feed hold** (``!``): the remaining profile turns into a deceleration at the block's
  acceleration, after the segments already prepared; once the machine has stopped the planner
  re-plans from rest and waits for :meth:`GrblExecutor.resume` (``~``).
- **Soft reset** (0x18): steps stop at once, both buffers are flushed and the planner position is
  synced to where the machine is; the return value says whether motion was in progress (Grbl then
  raises ``ALARM:3``, because steps may have been lost).
- **Dwell** (G4): waits for all motion to end (and the step idle delay), then ``delay_sec``
  waits ``ceil(20·P)`` steps of 50 ms (:attr:`~sim.grbl.planner.Dwell.duration`), checking
  real-time commands at the start of each step (:attr:`GrblExecutor.at_dwell_tick`); meanwhile
  the parser takes no other line.

Positions are kept in steps. :attr:`GrblExecutor.position_mm` is the machine position Grbl reports
(``sys_position``, counted by the step interrupt as it computes each step); the
:class:`Recorder` keeps the physical trace: the exact step positions at every segment boundary,
joined by straight lines (each segment runs at a constant step rate), sampled on a 1 ms grid on
request.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from sim.grbl.planner import (
    DWELL_TIME_STEP,
    PLANNER_CAPACITY,
    Dwell,
    GrblPlanner,
    GrblSettings,
    MotionBlock,
    PlanBlock,
    lround,
)

ACCELERATION_TICKS_PER_SECOND = 100
DT_SEGMENT = 1.0 / ACCELERATION_TICKS_PER_SECOND  # s
SEGMENT_BUFFER_SIZE = 6
SEGMENT_CAPACITY = SEGMENT_BUFFER_SIZE - 1  # ring buffer, one slot always empty
REQ_MM_INCREMENT_SCALAR = 1.25  # a segment must hold at least this many steps' worth
F_CPU = 16_000_000
_AMASS_LEVEL1 = F_CPU // 8000
_AMASS_LEVEL2 = F_CPU // 4000
_AMASS_LEVEL3 = F_CPU // 2000

_RAMP_ACCEL, _RAMP_CRUISE, _RAMP_DECEL, _RAMP_DECEL_OVERRIDE = 0, 1, 2, 3

IDLE, RUN, HOLD = "idle", "run", "hold"


class _Segment:
    """One prepared step segment: ``n_step`` step events of ``block`` at one constant rate."""

    __slots__ = ("block", "duration", "events_before", "n_step", "step_time", "t0")

    def __init__(
        self, block: PlanBlock, events_before: int, n_step: int, duration: float, step_time: float
    ) -> None:
        self.block = block
        self.events_before = events_before
        self.n_step = n_step
        self.duration = duration
        self.step_time = step_time
        self.t0 = 0.0


class Recorder:
    """The executed trace: exact knots at segment boundaries, linear in between.

    ``knots()`` returns the knots (times and positions in mm); ``trace(dt)`` samples them on a
    uniform grid (default 1 ms) from time 0 to the executor's current time, vectorised.
    """

    def __init__(self, t0: float, position_mm: tuple[float, float, float]) -> None:
        self._t: list[float] = [t0]
        self._p: list[tuple[float, float, float]] = [position_mm]
        self._now = t0

    def add(self, t: float, position_mm: tuple[float, float, float]) -> None:
        if t == self._t[-1]:
            self._p[-1] = position_mm
        else:
            self._t.append(t)
            self._p.append(position_mm)

    def _set_now(self, t: float) -> None:
        self._now = t

    def knots(self) -> tuple[np.ndarray, np.ndarray]:
        """Knot times ``(K,)`` and positions ``(K, 3)`` in mm, the last one held until now."""
        t = np.array(self._t, dtype=float)
        p = np.array(self._p, dtype=float).reshape(-1, 3)
        if self._now > t[-1]:
            t = np.append(t, self._now)
            p = np.vstack([p, p[-1]])
        return t, p

    def trace(self, dt: float = 0.001) -> np.ndarray:
        """``(N, 4)`` array of ``t, x, y, z`` every ``dt`` seconds (at most 1 ms) from time 0,
        ending with a sample at the current time."""
        if not (math.isfinite(dt) and 0 < dt <= 0.001):
            raise ValueError(f"dt: must be > 0 and <= 0.001 s, got {dt!r}")
        kt, kp = self.knots()
        n = math.floor((kt[-1] - kt[0]) / dt + 1e-9) + 1
        t = kt[0] + dt * np.arange(n)
        if kt[-1] - t[-1] > 1e-6:  # not a float's hair after the last grid sample
            t = np.append(t, kt[-1])
        out = np.empty((len(t), 4))
        out[:, 0] = t
        for axis in range(3):
            out[:, axis + 1] = np.interp(t, kt, kp[:, axis])
        return out


class GrblExecutor:
    """Grbl 1.1's planner + stepper against a simulated clock (seconds from 0).

    Feed it with :meth:`submit`; move time on with :meth:`advance` or :meth:`run_until`
    (see :meth:`cycle_start` for when motion begins).
    ``submit`` answers like Grbl's ``ok``: True once the item has been taken (a motion block
    queued in the planner, or dropped because it moves no step; a dwell finished), False when
    the parser would still be blocked on it (planner full, dwell not over); the caller then
    stops reading lines and offers the same item again later.
    """

    def __init__(
        self,
        settings: GrblSettings | None = None,
        position_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
        *,
        auto_start: bool = True,
        record: bool = True,
        planner_capacity: int = PLANNER_CAPACITY,
    ) -> None:
        self.settings = settings if settings is not None else GrblSettings()
        self.auto_start = auto_start
        self.now = 0.0
        spm = self.settings.steps_per_mm
        self._steps = tuple(lround(p * s) for p, s in zip(position_mm, spm, strict=True))
        self.planner = GrblPlanner(
            self.settings, self._steps, self._tail_replanned, capacity=planner_capacity
        )
        self.state = IDLE
        self.hold_complete = False
        self._exec_hold = False  # STEP_CONTROL_EXECUTE_HOLD
        self._end_motion = False  # STEP_CONTROL_END_MOTION
        self._reset_prep()
        self._queue: deque[_Segment] = deque()  # prepared, not started
        self._cur: _Segment | None = None  # executing segment
        self._cur_released = False  # its buffer slot freed (last step computed)
        self._dwell: Dwell | None = None
        self._dwell_end: float | None = None
        self._dwell_start: float | None = None
        self._frozen_at: float | None = None
        self._lock_until: float | None = None  # step idle delay running: main loop frozen
        self._pending_hold = False
        self.recorder: Recorder | None = Recorder(0.0, self.position_mm) if record else None
        self.on_cycle_stop: Callable[[], None] | None = None
        """Called when motion runs out of blocks and the machine stops (Run → Idle)."""
        self.last_planned: PlanBlock | None = None
        """The planner block the last accepted :meth:`submit` made (None: dropped, no step)."""
        self.on_block_done: Callable[[PlanBlock], None] | None = None
        """Called when a planner block's last step has been made (its last segment ended)."""

    # -- public state ------------------------------------------------------------------------

    @property
    def idle(self) -> bool:
        """No motion, nothing queued, no hold (a dwell still counts as idle, as in Grbl).

        Motion ends with the step idle delay ($1, 25 ms by default): Grbl still reports ``Run``
        then, and turns ``Idle`` after it.
        """
        return self.state == IDLE

    @property
    def free_blocks(self) -> int:
        """Planner blocks available (``Bf:`` first field); 15 when empty."""
        return self.planner.free_blocks

    @property
    def queued_blocks(self) -> int:
        return len(self.planner)

    @property
    def dwelling(self) -> bool:
        return self._dwell is not None

    @property
    def locked(self) -> bool:
        """True during the step idle delay ($1) after the last step of a motion: Grbl's step
        interrupt is busy waiting, so its main loop reads no line and sends no report."""
        return self._lock_until is not None and self._frozen_at is None

    @property
    def frozen(self) -> bool:
        """Motion is stalled by :meth:`freeze` (a fault hook)."""
        return self._frozen_at is not None

    @property
    def dwell_running(self) -> bool:
        """A dwell's ``delay_sec`` loop has begun (motion has ended) and the parser has not
        moved on from it yet (it does at the first :meth:`submit` from its end on)."""
        return self._dwell is not None and self._dwell_end is not None

    @property
    def at_dwell_tick(self) -> bool:
        """Now is one of the running dwell's 50 ms steps, where ``delay_sec`` lets real-time
        commands (status, reset, hold) through; the end of the dwell is not one."""
        end, start = self._dwell_end, self._dwell_start
        if not self.dwell_running or start is None or end is None:
            return False
        if self._frozen_at is not None:
            return True  # a stalled machine: its main loop answers at once
        if self.now >= end:
            return False
        k = (self.now - start) / DWELL_TIME_STEP
        return abs(k - round(k)) < 1e-6

    @property
    def position_steps(self) -> tuple[int, int, int]:
        """Machine position in steps, as the step interrupt has counted it by now."""
        seg = self._cur
        if seg is None:
            return self._steps
        now = self.now if self._frozen_at is None else self._frozen_at
        k = min(seg.n_step, int((now - seg.t0) / seg.step_time) + 1) if seg.n_step else 0
        return seg.block.steps_after(seg.events_before + k)

    @property
    def position_mm(self) -> tuple[float, float, float]:
        """Machine position in mm (Grbl's ``MPos``)."""
        return tuple(
            s / k for s, k in zip(self.position_steps, self.settings.steps_per_mm, strict=True)
        )  # type: ignore[return-value]

    @property
    def speed_mm_per_s(self) -> float:
        """Speed of the executing segment (0 when stopped)."""
        seg = self._cur
        if seg is None or seg.duration <= 0:
            return 0.0
        a = seg.block.steps_after(seg.events_before)
        b = seg.block.steps_after(seg.events_before + seg.n_step)
        d = math.sqrt(
            sum(
                ((j - i) / k) ** 2 for i, j, k in zip(a, b, self.settings.steps_per_mm, strict=True)
            )
        )
        return d / seg.duration

    @property
    def reported_rate_mm_per_min(self) -> float:
        """What Grbl's status report shows as ``FS:<rate>``: the speed at the end of the last
        *prepared* segment (up to ~50 ms ahead of the motion), 0 when idle."""
        if self.state == IDLE:
            return 0.0
        return self._p_current_speed * 60.0

    # -- feeding -----------------------------------------------------------------------------

    def submit(self, item: MotionBlock | Dwell) -> bool:
        """Offer the parser's next item. True = accepted (Grbl would send ``ok`` now)."""
        if self._lock_until is not None:
            return False
        if self._dwell is not None:
            end = self._dwell_end
            if item == self._dwell and end is not None and self.now >= end and not self.frozen:
                self._dwell = None
                self._dwell_end = self._dwell_start = None
                return True
            return False
        if isinstance(item, Dwell):
            self._dwell = item
            if self._motion_done():
                if item.ticks <= 0:
                    self._dwell = None
                    return True
                self._start_dwell()
            else:
                self._auto_cycle_start()
            return False
        if not isinstance(item, MotionBlock):
            raise TypeError(f"item: expected MotionBlock or Dwell, got {type(item).__name__}")
        if self.planner.full:
            self._auto_cycle_start()
            return False
        self.last_planned = self.planner.buffer_line(item)
        if self.last_planned is None:
            return True  # zero-length block: acknowledged, nothing queued
        if self.state == RUN:
            self._prep_buffer()
            self._wake_up()
        elif self.state == HOLD and not self.hold_complete:
            self._prep_buffer()  # a hold still decelerating may carry on into the new block
        # A completed hold prepares nothing (Grbl's END_MOTION): the block waits for the resume.
        elif self.auto_start:
            self._auto_cycle_start()
        return True

    def freeze(self, frozen: bool = True) -> None:
        """Stall the machine (a fault hook): no step, no segment or block ends, the dwell and
        the step idle delay stop counting; the position holds. ``freeze(False)`` carries on
        where it stopped, every pending time shifted by the stall."""
        if frozen and self._frozen_at is None:
            self._frozen_at = self.now
            if self.recorder is not None:
                self.recorder.add(self.now, self.position_mm)
        elif not frozen and self._frozen_at is not None:
            shift = self.now - self._frozen_at
            if self.recorder is not None:
                self.recorder.add(self.now, self.position_mm)
            self._frozen_at = None
            if self._cur is not None:
                self._cur.t0 += shift
            if self._lock_until is not None:
                self._lock_until += shift
            if self._dwell_end is not None and self._dwell_start is not None:
                self._dwell_start += shift
                self._dwell_end += shift
            self._wake_up()

    def cycle_start(self) -> None:
        """Grbl's auto cycle start: begin executing queued blocks if idle.

        Grbl starts motion only when its parser runs out of input (serial buffer empty), when
        the planner is full, or when a command waits for motion to end (G4). With
        ``auto_start=True`` (the default) every accepted block counts as "input ran out"; a
        serial device that knows its receive buffer should pass ``auto_start=False`` and call
        this whenever the buffer runs dry, which is what delays the start of a character-counted
        stream until the planner has filled.
        """
        self._auto_cycle_start()

    # -- time --------------------------------------------------------------------------------

    def advance(self, dt: float) -> None:
        """Move simulated time on by ``dt`` seconds."""
        if not (math.isfinite(dt) and dt >= 0):
            raise ValueError(f"dt: must be a finite number >= 0, got {dt!r}")
        self.run_until(self.now + dt)

    def run_until(self, t: float, until: Callable[[], bool] | None = None) -> bool:
        """Run to time ``t``, or to the first internal event at which ``until()`` holds.

        Internal events are segment boundaries (where planner slots free up and motion can end)
        and the end of a dwell. Returns True if stopped by ``until``; ``t`` may be ``inf`` when
        ``until`` is given and will become true.
        """
        if math.isnan(t):
            raise ValueError("t: must not be NaN")
        while True:
            if until is not None and until():
                self._touch()
                return True
            event = self._next_event()
            if event is None or event > t:
                if math.isinf(t):
                    if until is None:
                        raise ValueError("t: cannot run to infinity without a condition")
                    raise RuntimeError("condition can never become true: nothing left to run")
                self.now = max(self.now, t)
                self._touch()
                return False
            self.now = max(self.now, event)
            self._handle_event()

    def move_clock(self, t: float) -> None:
        """:meth:`run_until` ``t`` when no internal event comes by then (:meth:`next_event` is
        later, or None): only the clock moves."""
        self.now = max(self.now, t)
        self._touch()

    def run_until_idle(self, limit: float = math.inf) -> bool:
        """Run until the machine is idle (or time ``limit``). True if it became idle."""
        if self._motion_done():
            return True
        return self.run_until(limit, until=self._motion_done)

    # -- real-time commands ------------------------------------------------------------------

    def feed_hold(self) -> None:
        """``!``: decelerate to a stop at the planned acceleration, then wait for resume."""
        if self._lock_until is not None:
            self._pending_hold = True
        elif self.state == RUN:
            self._tail_replanned()
            self._exec_hold = True
            self.state = HOLD
            self.hold_complete = False
            self._prep_buffer()
        elif self.state == IDLE:
            self.state = HOLD
            self.hold_complete = True

    def resume(self) -> bool:
        """``~``: resume after a completed hold. Ignored (False) while still decelerating."""
        if self.state != HOLD or not self.hold_complete or self._lock_until is not None:
            return False
        self._exec_hold = False
        self._end_motion = False
        self.hold_complete = False
        if self.planner.current_block() is not None:
            self.state = RUN
            self._prep_buffer()
            self._wake_up()
        else:
            self.state = IDLE
            self._maybe_start_dwell()
        return True

    def soft_reset(self) -> bool:
        """Ctrl-X: stop at once and flush. True if motion was in progress (→ ``ALARM:3``)."""
        in_motion = self.state == RUN or self._exec_hold
        self._steps = self.position_steps
        self._cur = None
        self._queue.clear()
        self._reset_prep()
        self._exec_hold = self._end_motion = False
        self.hold_complete = False
        self.state = IDLE
        self._dwell = self._dwell_end = self._dwell_start = None
        self._lock_until = None
        self._pending_hold = False
        self.planner.reset(self._steps)
        if self.recorder is not None:
            self.recorder.add(self.now, self.position_mm)
        return in_motion

    def configure(self, settings: GrblSettings) -> None:
        """Change settings ($ commands); only while idle with nothing queued, as Grbl requires."""
        if not self._motion_done() or len(self.planner):
            raise RuntimeError("settings can only change while idle")
        self.settings = settings
        self.planner = GrblPlanner(
            settings, self._steps, self._tail_replanned, capacity=self.planner.capacity
        )

    # -- internals: cycle control ------------------------------------------------------------

    def _motion_done(self) -> bool:
        return self.state == IDLE and self._cur is None and not self.planner.blocks

    def _auto_cycle_start(self) -> None:
        if self.state == IDLE and self.planner.current_block() is not None:
            self.state = RUN
            self._prep_buffer()
            self._wake_up()

    def _wake_up(self) -> None:
        """Start executing the next prepared segment if the stepper is stopped."""
        if self._cur is None and self._queue and self._frozen_at is None:
            self._start_next(self.now)

    def _start_next(self, t: float) -> None:
        seg = self._queue.popleft()
        seg.t0 = t
        if self.recorder is not None:
            self.recorder.add(t, self._mm(self._steps))
        self._cur = seg
        self._cur_released = seg.n_step <= 1
        if self._cur_released:
            self._prep_buffer()

    def next_event(self) -> float | None:
        """The time of the next internal event (see :meth:`run_until`), None when there is none."""
        return self._next_event()

    def _next_event(self) -> float | None:
        if self._frozen_at is not None:
            return None
        events = []
        seg = self._cur
        if seg is not None:
            if self._cur_released:
                events.append(seg.t0 + seg.duration)
            else:
                events.append(seg.t0 + (seg.n_step - 1) * seg.step_time)
        start, end = self._dwell_start, self._dwell_end
        if self.dwell_running and start is not None and end is not None and self.now < end:
            # delay_sec's next 50 ms step (a real-time check point), or the end.
            k = math.floor((self.now - self._dwell_start) / DWELL_TIME_STEP + 1e-6) + 1
            events.append(min(self._dwell_start + k * DWELL_TIME_STEP, self._dwell_end))
        if self._lock_until is not None:
            events.append(self._lock_until)
        return min(events) if events else None

    def _handle_event(self) -> None:
        seg = self._cur
        now = self.now
        if seg is not None:
            if not self._cur_released and now >= seg.t0 + (seg.n_step - 1) * seg.step_time:
                # The step interrupt computed the segment's last step: its buffer slot frees.
                self._cur_released = True
                self._prep_buffer()
                return
            if self._cur_released and now >= seg.t0 + seg.duration:
                self._finish_segment(seg)
                return
        if self._lock_until is not None and now >= self._lock_until:
            self._lock_until = None
            if self._pending_hold:
                # A feed hold that came in during the delay is handled before the cycle stop.
                self._pending_hold = False
                if self.state == RUN:
                    self.state = HOLD
                    self._exec_hold = True
            self._cycle_stop()
            return
        # Otherwise a dwell has ended; nothing to do until the parser comes back for it.

    def _finish_segment(self, seg: _Segment) -> None:
        done = seg.events_before + seg.n_step
        self._steps = seg.block.steps_after(done)
        self._cur = None
        if self.recorder is not None:
            self.recorder.add(self.now, self._mm(self._steps))
        if done >= seg.block.step_event_count and self.on_block_done is not None:
            self.on_block_done(seg.block)
        if self._queue:
            self._start_next(self.now)
            return
        # Segment buffer empty: the interrupt stops the motors, holds them for the step idle
        # delay ($1, busy-waiting inside the interrupt), then flags a cycle stop.
        delay = self.settings.idle_lock_delay_s
        if delay > 0:
            self._lock_until = self.now + delay
        else:
            self._cycle_stop()

    def _cycle_stop(self) -> None:
        if self.state == HOLD:
            if self._exec_hold or self._end_motion:
                self.planner.cycle_reinitialize()
                self.hold_complete = True
                self._exec_hold = False
        elif self.state == RUN:
            self.state = IDLE
            self._end_motion = False
            if self.on_cycle_stop is not None:
                self.on_cycle_stop()
            if self.planner.current_block() is not None:  # pragma: no cover - defensive
                self._auto_cycle_start()
            else:
                self._maybe_start_dwell()

    def _maybe_start_dwell(self) -> None:
        if self._dwell is not None and self._dwell_end is None and self._motion_done():
            self._start_dwell()

    def _start_dwell(self) -> None:
        assert self._dwell is not None
        start = self.now if self._frozen_at is None else self._frozen_at
        self._dwell_start = start
        self._dwell_end = start + self._dwell.duration

    def _touch(self) -> None:
        if self.recorder is not None:
            self.recorder._set_now(self.now)
        if self._dwell is not None and self._dwell_end is None:
            self._maybe_start_dwell()

    def _mm(self, steps: tuple[int, int, int]) -> tuple[float, float, float]:
        return tuple(s / k for s, k in zip(steps, self.settings.steps_per_mm, strict=True))  # type: ignore[return-value]

    # -- internals: segment preparation (st_prep_buffer) ------------------------------------

    def _reset_prep(self) -> None:
        self._p_block: PlanBlock | None = None
        self._p_recalculate = False
        self._p_decel_override = False
        self._p_steps_remaining = 0.0
        self._p_step_per_mm = 0.0
        self._p_req_mm_increment = 0.0
        self._p_dt_remainder = 0.0
        self._p_current_speed = 0.0
        self._p_exit_speed = 0.0
        self._p_mm_complete = 0.0
        self._p_ramp = _RAMP_ACCEL
        self._p_accelerate_until = 0.0
        self._p_decelerate_after = 0.0
        self._p_maximum_speed = 0.0

    def _tail_replanned(self) -> None:
        """``st_update_plan_block_parameters``: re-profile the block being prepared."""
        blk = self._p_block
        if blk is not None:
            self._p_recalculate = True
            blk.entry_speed_sqr = self._p_current_speed * self._p_current_speed
            self._p_block = None

    def _segments_in_buffer(self) -> int:
        busy = 1 if (self._cur is not None and not self._cur_released) else 0
        return len(self._queue) + busy

    def _load_block(self) -> PlanBlock | None:
        """Load (or re-profile) the tail planner block; None if the planner is empty."""
        blk = self.planner.current_block()
        if blk is None:
            return None
        self._p_block = blk
        if self._p_recalculate:
            self._p_recalculate = False
        else:
            n = float(blk.step_event_count)
            self._p_steps_remaining = n
            self._p_step_per_mm = n / blk.millimeters
            self._p_req_mm_increment = REQ_MM_INCREMENT_SCALAR / self._p_step_per_mm
            self._p_dt_remainder = 0.0
            if self._exec_hold or self._p_decel_override:
                # New block loaded mid-hold: keep decelerating from where the last one ended.
                self._p_current_speed = self._p_exit_speed
                blk.entry_speed_sqr = self._p_exit_speed * self._p_exit_speed
                self._p_decel_override = False
            else:
                self._p_current_speed = math.sqrt(blk.entry_speed_sqr)

        # Velocity profile of the (remaining) block.
        self._p_mm_complete = 0.0
        accel = blk.acceleration
        inv_2_accel = 0.5 / accel
        mm = blk.millimeters
        if self._exec_hold:
            # Forced deceleration to zero speed.
            self._p_ramp = _RAMP_DECEL
            decel_dist = mm - inv_2_accel * blk.entry_speed_sqr
            if decel_dist < 0.0:
                self._p_exit_speed = math.sqrt(max(blk.entry_speed_sqr - 2 * accel * mm, 0.0))
            else:
                self._p_mm_complete = decel_dist
                self._p_exit_speed = 0.0
            return blk
        self._p_ramp = _RAMP_ACCEL
        self._p_accelerate_until = mm
        exit_speed_sqr = self.planner.exit_speed_sqr_of_current()
        self._p_exit_speed = math.sqrt(exit_speed_sqr)
        nominal = blk.nominal_speed
        nominal_sqr = nominal * nominal
        entry_sqr = blk.entry_speed_sqr
        intersect = 0.5 * (mm + inv_2_accel * (entry_sqr - exit_speed_sqr))
        if entry_sqr > nominal_sqr:
            # Only with overrides in Grbl; kept for completeness (entry above nominal).
            self._p_accelerate_until = mm - inv_2_accel * (entry_sqr - nominal_sqr)
            if self._p_accelerate_until <= 0.0:
                self._p_ramp = _RAMP_DECEL
                self._p_exit_speed = math.sqrt(max(entry_sqr - 2 * accel * mm, 0.0))
                self._p_decel_override = True
            else:
                self._p_decelerate_after = inv_2_accel * (nominal_sqr - exit_speed_sqr)
                self._p_maximum_speed = nominal
                self._p_ramp = _RAMP_DECEL_OVERRIDE
        elif intersect > 0.0:
            if intersect < mm:  # trapezoid or triangle
                self._p_decelerate_after = inv_2_accel * (nominal_sqr - exit_speed_sqr)
                if self._p_decelerate_after < intersect:  # trapezoid
                    self._p_maximum_speed = nominal
                    if entry_sqr == nominal_sqr:
                        self._p_ramp = _RAMP_CRUISE
                    else:
                        self._p_accelerate_until -= inv_2_accel * (nominal_sqr - entry_sqr)
                else:  # triangle
                    self._p_accelerate_until = intersect
                    self._p_decelerate_after = intersect
                    self._p_maximum_speed = math.sqrt(2.0 * accel * intersect + exit_speed_sqr)
            else:  # deceleration only
                self._p_ramp = _RAMP_DECEL
        else:  # acceleration only
            self._p_accelerate_until = 0.0
            self._p_maximum_speed = self._p_exit_speed
        return blk

    def _prep_buffer(self) -> None:
        """``st_prep_buffer``: fill the segment buffer from the tail planner block."""
        if self._end_motion or self.state == IDLE:
            return
        while self._segments_in_buffer() < SEGMENT_CAPACITY:
            blk = self._p_block
            if blk is None:
                blk = self._load_block()
                if blk is None:
                    return
            if not self._prep_segment(blk):
                return

    def _prep_segment(self, blk: PlanBlock) -> bool:
        """Prepare one segment of ``blk``. False when preparation must stop (end of a hold)."""
        accel = blk.acceleration
        dt_max = DT_SEGMENT
        dt = 0.0
        time_var = dt_max
        mm_remaining = blk.millimeters
        minimum_mm = max(mm_remaining - self._p_req_mm_increment, 0.0)
        mm_complete = self._p_mm_complete
        speed = self._p_current_speed
        ramp = self._p_ramp
        accelerate_until = self._p_accelerate_until
        decelerate_after = self._p_decelerate_after
        maximum_speed = self._p_maximum_speed
        exit_speed = self._p_exit_speed
        # Distances are measured back from the end of the block. ``block_mm`` is what was left at
        # the start of this segment; the acceleration ramps only ever run in a segment's first
        # pass, so ramp-junction times are measured from it.
        block_mm = blk.millimeters
        while True:
            if ramp == _RAMP_DECEL_OVERRIDE:
                speed_var = accel * time_var
                if speed - maximum_speed <= speed_var:
                    mm_remaining = accelerate_until
                    time_var = 2.0 * (block_mm - mm_remaining) / (speed + maximum_speed)
                    ramp = _RAMP_CRUISE
                    speed = maximum_speed
                else:
                    mm_remaining -= time_var * (speed - 0.5 * speed_var)
                    speed -= speed_var
            elif ramp == _RAMP_ACCEL:
                speed_var = accel * time_var
                mm_remaining -= time_var * (speed + 0.5 * speed_var)
                if mm_remaining < accelerate_until:
                    mm_remaining = accelerate_until
                    time_var = 2.0 * (block_mm - mm_remaining) / (speed + maximum_speed)
                    ramp = _RAMP_DECEL if mm_remaining == decelerate_after else _RAMP_CRUISE
                    speed = maximum_speed
                else:
                    speed += speed_var
            elif ramp == _RAMP_CRUISE:
                mm_var = mm_remaining - maximum_speed * time_var
                if mm_var < decelerate_after:
                    time_var = (mm_remaining - decelerate_after) / maximum_speed
                    mm_remaining = decelerate_after
                    ramp = _RAMP_DECEL
                else:
                    mm_remaining = mm_var
            else:  # _RAMP_DECEL
                speed_var = accel * time_var
                finished = True
                if speed > speed_var:
                    mm_var = mm_remaining - time_var * (speed - 0.5 * speed_var)
                    if mm_var > mm_complete:
                        mm_remaining = mm_var
                        speed -= speed_var
                        finished = False
                if finished:
                    both = speed + exit_speed
                    time_var = 2.0 * (mm_remaining - mm_complete) / both if both > 0 else 0.0
                    mm_remaining = mm_complete
                    speed = exit_speed
            dt += time_var
            if dt < dt_max:
                time_var = dt_max - dt  # incomplete segment at a ramp junction: go on
            elif mm_remaining > minimum_mm:
                # Too slow to hold a step yet: lengthen the segment.
                dt_max += DT_SEGMENT
                time_var = dt_max - dt
            else:
                break
            if not mm_remaining > mm_complete:
                break

        self._p_current_speed = speed
        self._p_ramp = ramp

        # Whole steps of this segment, with the previous segment's partial step carried over.
        step_per_mm = self._p_step_per_mm
        step_dist_remaining = step_per_mm * mm_remaining
        n_steps_remaining = math.ceil(step_dist_remaining)
        last_n_steps_remaining = math.ceil(self._p_steps_remaining)
        n_step = last_n_steps_remaining - n_steps_remaining
        if n_step == 0 and self._exec_hold:
            # Less than a step left to decelerate: the hold ends here.
            self._end_motion = True
            return False
        dt += self._p_dt_remainder
        denom = last_n_steps_remaining - step_dist_remaining
        inv_rate = dt / denom if denom > 0 else 0.0  # s per step
        if n_step > 0:
            cycles = math.ceil(F_CPU * inv_rate)
            if cycles < _AMASS_LEVEL1:
                level = 0
            elif cycles < _AMASS_LEVEL2:
                level = 1
            elif cycles < _AMASS_LEVEL3:
                level = 2
            else:
                level = 3
            per_tick = min(cycles >> level, 0xFFFF)
            step_time = (per_tick << level) / F_CPU
            duration = n_step * step_time
        else:
            step_time = 0.0
            duration = 0.0
        events_before = blk.step_event_count - last_n_steps_remaining
        self._queue.append(_Segment(blk, events_before, n_step, duration, step_time))

        blk.millimeters = mm_remaining
        self._p_steps_remaining = float(n_steps_remaining)
        self._p_dt_remainder = (n_steps_remaining - step_dist_remaining) * inv_rate

        if mm_remaining == mm_complete:
            if mm_remaining > 0.0:
                # End of a forced deceleration (feed hold) inside this block.
                self._end_motion = True
                return False
            # Block fully prepared: discard it from the planner, freeing a slot.
            self._p_block = None
            self.planner.discard_current_block()
        return True


__all__ = [
    "ACCELERATION_TICKS_PER_SECOND",
    "DT_SEGMENT",
    "HOLD",
    "IDLE",
    "PLANNER_CAPACITY",
    "RUN",
    "SEGMENT_CAPACITY",
    "GrblExecutor",
    "Recorder",
]
