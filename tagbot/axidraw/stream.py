"""Streaming a job's moves to an EiBotBoard (firmware 3.x, legacy response mode).

**Connect.** ``V`` reads the firmware version; below :data:`MIN_FIRMWARE` the run is refused
before any motion command (``LT``/``T3``, the settable FIFO and ``QU,6`` need 3.0.1). Then
``QU,2`` (the largest FIFO the firmware has) and ``CU,4,n`` (the depth asked, capped there),
``EM`` (motors on, the profile's microstepping; it also zeroes the step counters),
``SC,8`` (servo channels: the pen servo's pulse period) and ``SC,4``/``SC,5``/``SC,11``/
``SC,12`` (pen positions and rates); the job's first line is then a pen-up ``SP,1`` (see
:mod:`tagbot.axidraw.machine`). A profile may ask a later firmware
(``machine.min_firmware``: 3.0.2 for the NextDraws, as the makers' NextDraw software does).

**Stream.** A motion command is sent only while the board has room for it (one executing, ``n``
in the FIFO), so the board answers it at once and its queries stay answered: every
``serial.poll`` s (and whenever the FIFO is full) ``QM`` (executing?), ``QU,6`` (commands
waiting) and ``QS`` (global step position) say what has executed:
``executed = sent − waiting − executing`` (read in that order, a race can only count one move
fewer, never one more), and ``QB`` (the PRG button) asks for a pause.

A **stall** is the board found idle when the host sends again while the job has more, or a
send held up past when the board's queue should have ended, after which that line alone is on
the board: the host was late (descheduled, a stalled USB); it lasts from when the last command
sent should have ended until then (:attr:`StreamReport.stalls`, the report's ``stalls``). A
line is not counted to start before the board has answered it.

**Pause** (the button or :class:`~tagbot.control.RunControl`): nothing more is sent, the FIFO
drains, the pen lifts (``SP,1``) and waits; on resume the pen lowers and the stream goes on from
the next move: the motors never moved, so the motion after it is the plan's, exactly.

**Stop** (Ctrl-C, SIGTERM, a board error, a lost line): ``ES`` (motion stops, the FIFO is
flushed), ``QS`` (where the motors stopped), pen up. The move in progress is found from the
stopped position along the job's tick record (:meth:`EBBStreamer.locate`).
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from firmware_protocols.ebb.motion import TICK_HZ
from tagbot.axidraw.profile import MIN_FIRMWARE, Profile
from tagbot.clock import port_clock
from tagbot.control import RunControl
from tagbot.errors import ConnectionLost, DeviceError, DeviceFault, DeviceTimeout

if TYPE_CHECKING:
    from tagbot.axidraw.moves import Job

__all__ = ["MIN_FIRMWARE", "EBBStreamer", "StreamReport", "parse_version"]

REPLY_TIMEOUT = 2.0
"""s a reply may take (the board answers every command at once: tagbot never fills its FIFO)."""

_RECHECK = 0.001
"""s between asks while the board is behind its plan and the FIFO is full."""

RESYNC_TIMEOUT = 10.0
"""s a stop waits for the board to answer again (a stalled USB) before giving up."""

_VERSION = re.compile(rb"Version\s+(\d+)\.(\d+)\.(\d+)")


def parse_version(reply: bytes) -> tuple[int, int, int]:
    """The firmware version in a ``V`` reply (``EBBv13_and_above EB Firmware Version 3.0.2``)."""
    found = _VERSION.search(reply)
    if found is None:
        raise DeviceError(f"V: not an EiBotBoard's version reply: {reply!r}")
    return int(found[1]), int(found[2]), int(found[3])


@dataclass
class StreamReport:
    """What a stream sent, what executed and when (times on the port's clock)."""

    firmware: tuple[int, int, int] = (0, 0, 0)
    fifo: int = 1
    first: int = 0
    """The first entry streamed (0-based; > 0 when resuming)."""
    sent: int = 0
    """Entries sent and acknowledged, counting from :attr:`first`."""
    executed: int = 0
    """Entries executed in full, counting from the job's first."""
    started: float = 0.0
    ended: float = 0.0
    polls: list[tuple[float, int, int, int]] = field(default_factory=list)
    """``(t, executed, motor 1, motor 2)`` at each ``QS``."""
    pauses: list[tuple[float, float]] = field(default_factory=list)
    stalls: list[tuple[float, float]] = field(default_factory=list)
    """The board found idle when the host sent its next command: from when the last one
    should have ended to then (the host was late: a descheduled host, a slow USB)."""
    stopped_at: tuple[int, int] | None = None
    """Global steps where ``ES`` stopped the motors (None: the job ran to its end)."""
    button_presses: int = 0
    most_on_board: int = 0
    """The most job commands the board held at once (one executing, the FIFO's): at most
    ``fifo + 1``, so the board always has room and answers every query at once."""
    errors: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        return self.ended - self.started


class EBBStreamer:
    """One EBB on an open serial ``link`` (pyserial-like: ``write``, ``read``)."""

    def __init__(
        self, link: Any, profile: Profile, pens: Mapping[bool, tuple[bytes, float]]
    ) -> None:
        """``pens[down]``: the job's ``SP`` line lowering (True) or lifting the pen, and how
        long it takes (s), for pauses, stops and resumes."""
        self.link = link
        self.profile = profile
        self.pens = pens
        self.clock = port_clock(link)
        self.report = StreamReport()
        self._buffer = b""

    # -- the wire ---------------------------------------------------------------------------
    def _line(self, command: bytes, timeout: float = REPLY_TIMEOUT) -> bytes:
        """The next non-empty reply line (legacy mode ends lines with CR, LF or both). Late
        only if a read after the deadline brings nothing (a host descheduled past it finds the
        reply waiting)."""
        deadline = self.clock.now() + timeout
        while True:
            parts = re.split(rb"[\r\n]+", self._buffer.lstrip(b"\r\n"), maxsplit=1)
            if len(parts) == 2:
                self._buffer = parts[1]
                return parts[0]
            expired = self.clock.now() >= deadline
            try:
                chunk = self.link.read(max(1, getattr(self.link, "in_waiting", 0) or 1))
            except (OSError, ValueError) as e:
                raise ConnectionLost(f"the EBB's line failed: {e}") from e
            self._buffer += chunk
            if expired and not chunk:
                name = command.split(b",")[0].strip().decode("ascii", "replace")
                raise DeviceTimeout(f"{name}: no reply from the EBB in {timeout:g} s")

    def ask(self, command: str | bytes, *, data: bool = False, ok: bool = True) -> bytes:
        """Send ``command`` (``\\r`` added); its data line if ``data``, then ``OK`` if ``ok``.
        An error line (``!N Err: ...``) is a :class:`DeviceFault` naming the command."""
        line = self._send(command)
        answer = b""
        if data:
            answer = self._checked(line, self._line(line))
        if ok:
            end = self._checked(line, self._line(line))
            if end != b"OK":
                raise DeviceError(f"{_name(line)}: expected OK from the EBB, got {end!r}")
        return answer

    def _send(self, command: str | bytes) -> bytes:
        line = command.encode("ascii") if isinstance(command, str) else command
        line = line if line.endswith(b"\r") else line + b"\r"
        try:
            self.link.write(line)
        except (OSError, ValueError) as e:
            raise ConnectionLost(f"the EBB's line failed: {e}") from e
        return line

    def _resync(self) -> None:
        """Drop every reply in flight (after a late one, replies no longer match asks): ask
        ``V`` and read up to its reply, waiting up to :data:`RESYNC_TIMEOUT` s."""
        line = self._send("V")
        deadline = self.clock.now() + RESYNC_TIMEOUT
        while not _VERSION.search(self._line(line, max(0.0, deadline - self.clock.now()))):
            pass

    def _checked(self, line: bytes, reply: bytes) -> bytes:
        if reply.startswith(b"!"):
            text = reply.decode("ascii", "replace")
            self.report.errors.append(text)
            raise DeviceFault(f"{line.strip().decode('ascii', 'replace')}: the EBB replied {text}")
        return reply

    # -- connect ----------------------------------------------------------------------------
    def connect(
        self, *, keep_position: bool = False, fifo: int | None = None
    ) -> tuple[int, int, int]:
        """Version, FIFO depth, motors and pen set up (module docstring); the version.

        ``EM`` clears the board's step counters: the job's steps count from where the motors
        are (home), or with ``keep_position`` (a resume) from where the counters said they
        were before it. ``fifo``: the depth the job's short moves need, when more than the
        profile's ``serial.fifo`` (:attr:`tagbot.axidraw.moves.Job.fifo`)."""
        p = self.profile
        version = parse_version(self.ask("V", data=True, ok=False))
        self.report.firmware = version
        oldest = max(MIN_FIRMWARE, p.min_firmware)
        if version < oldest:
            have = ".".join(map(str, version))
            need = ".".join(map(str, oldest))
            why = "LT/T3 moves, a deep FIFO" if oldest == MIN_FIRMWARE else p["machine.model"]
            raise DeviceError(
                f"EBB firmware {have} is not supported: tagbot needs {need} or later ({why}); "
                "update it with the makers' EBB firmware updater"
            )
        largest = int(self.ask("QU,2", data=True).split(b",")[-1])
        depth = max(1, min(max(int(p["serial.fifo"]), fifo or 0), largest))
        self.ask(f"CU,4,{depth}")
        self.report.fifo = depth
        before = self.position()
        self.ask(f"EM,{p.step_mode},{p.step_mode}")
        self.origin = before if keep_position else (0, 0)
        self.ask(f"SC,8,{p.servo_channels}")
        self.ask(f"SC,4,{p.servo_position(p['pen.up'])}")
        self.ask(f"SC,5,{p.servo_position(p['pen.down'])}")
        self.ask(f"SC,11,{p.servo_rate(p['pen.rate_raise'])}")
        self.ask(f"SC,12,{p.servo_rate(p['pen.rate_lower'])}")
        self.ask("QB", data=True)  # forget a press from before the job
        return version

    origin: tuple[int, int] = (0, 0)
    """The job's step position where the board's counters read 0."""

    def position(self) -> tuple[int, int]:
        """The job's step position: the board's global step counters (``QS``) + origin."""
        a, b = self.ask("QS", data=True).split(b",")
        return int(a) + self.origin[0], int(b) + self.origin[1]

    def pen_line(self, down: bool) -> bytes:
        """The job's own ``SP`` lowering (``down``) or lifting the pen."""
        return self.pens[down][0]

    # -- stream -----------------------------------------------------------------------------
    def stream(
        self,
        lines: Sequence[bytes],
        *,
        durations: Sequence[float],
        first: int = 0,
        preamble: Sequence[bytes] = (),
        pen_down: Sequence[bool] = (),
        progress: Callable[[int, int], None] | None = None,
        control: RunControl | None = None,
    ) -> StreamReport:
        """Send ``preamble`` then ``lines[first:]`` (module docstring); ``durations[i]``: line
        ``i``'s planned s (when the board will have room again); ``pen_down[i]``: the pen is
        down once line ``i`` has executed (for a pause's lift and lowering)."""
        r = self.report
        r.first, r.executed = first, first
        r.started = self.clock.now()
        depth = r.fifo + 1  # one executing, the rest in the FIFO
        poll = float(self.profile["serial.poll"])
        for line in preamble:  # a resume's travel and pen: done before the job's moves
            self.ask(line)
            self._drain(self.clock.now(), poll)
        total = len(lines)
        finish: deque[float] = deque()  # when each outstanding line should be done
        last: float | None = None  # when the last line sent should be done
        next_poll = self.clock.now()
        sent = first
        while sent < total or self._outstanding:
            now = self.clock.now()
            if sent < total and self._outstanding < depth:
                due = last  # when the board runs out of what it holds
                if last is not None and now > last + _RECHECK:  # late: did the board run dry?
                    self._count(sent)
                    if not self._outstanding:
                        r.stalls.append((last, now - last))
                    last, due = now, None  # the board is at least this far behind the estimate
                self.ask(lines[sent])
                after = self.clock.now()
                last = max(after, last if last is not None else after) + durations[sent]
                finish.append(last)
                sent += 1
                r.sent = sent - first
                self._outstanding += 1
                r.most_on_board = max(r.most_on_board, self._outstanding)
                if due is not None and after > due + _RECHECK:  # held up in the send itself
                    self._count(sent)
                    if self._outstanding <= 1:  # only this line: the board had run dry
                        r.stalls.append((due, after - due))
                continue
            if now >= next_poll:
                next_poll = now + poll
                self._poll(sent)
                if progress is not None:
                    progress(r.executed, total)
                button = self._button()
                if button or (control is not None and control.paused):
                    down = bool(pen_down[sent - 1]) if pen_down and sent > first else False
                    self._pause(down, None if button else control, sent, poll)
                    finish.clear()
                    last = None
            else:  # full: ask again when the oldest line should be done
                wake = min(next_poll, finish[0] if finish else next_poll)
                self.clock.sleep_until(max(wake, now + _RECHECK))
                self._count(sent)
            while len(finish) > self._outstanding:
                finish.popleft()
        r.ended = self.clock.now()
        if progress is not None:
            progress(r.executed, total)
        return r

    _outstanding = 0

    def _state(self) -> int:
        """Motion commands on the board (``QM`` executing, then ``QU,6`` waiting)."""
        status = self.ask("QM", data=True, ok=False).split(b",")
        executing = int(status[1]) if len(status) == 5 else 0
        return executing + int(self.ask("QU,6", data=True).split(b",")[-1])

    def _count(self, sent_to: int) -> None:
        """What has executed (module docstring)."""
        self.report.executed = max(self.report.executed, sent_to - self._state())
        self._outstanding = sent_to - self.report.executed

    def _poll(self, sent_to: int) -> None:
        """What has executed, and where the motors are."""
        self._count(sent_to)
        steps = self.position()
        self.report.polls.append((self.clock.now(), self.report.executed, *steps))

    def _drain(self, until: float, step: float = _RECHECK) -> None:
        """Wait until the board has executed every motion command it holds: first until
        ``until`` (when it should have), then asking every ``step`` s."""
        self.clock.sleep_until(until)
        while self._state():
            self.clock.sleep_until(self.clock.now() + step)

    def _button(self) -> bool:
        """``QB``: the PRG button pressed since the last ask."""
        pressed = self.ask("QB", data=True).strip() == b"1"
        self.report.button_presses += pressed
        return pressed

    def _pause(self, down: bool, control: RunControl | None, sent_to: int, poll: float) -> None:
        """Drain (asking every ms, so the pause starts as the motors stop), lift, wait for the
        resume (``control``, or without it the button pressed again), lower: the pause is from
        the motors' stop to the pen's return, and the stream goes on at once. A stop while
        paused ends the pause there."""
        self._drain(self.clock.now())
        self._count(sent_to)
        start = self.clock.now()
        try:
            if down:
                self.ask(self.pen_line(False))
            while True:
                self.clock.sleep_until(self.clock.now() + poll)
                pressed = self._button()
                if (control is None and pressed) or (control is not None and not control.paused):
                    break
            if down:
                self.ask(self.pen_line(True))
                self._drain(self.clock.now() + self.pens[True][1])
        finally:
            self.report.pauses.append((start, self.clock.now() - start))

    def stop(self) -> tuple[int, int] | None:
        """``ES``, ``QS``, pen up (waited for); the stopped position (None if the board did
        not answer)."""
        try:
            self._send("ES")  # first: the motors stop as soon as it arrives
            self._resync()  # past its reply and any late one
            steps = self.position()
            if False in self.pens:  # a job without pen moves never lowered it
                self.ask(self.pen_line(False))
                self._drain(self.clock.now() + self.pens[False][1])  # the pen is up
        except DeviceError:
            return None
        self.report.stopped_at = steps
        self.report.ended = self.clock.now()
        return steps


def locate(job: Job, steps: tuple[int, int], after: int, before: int) -> int:
    """Entries executed in full when the motors stood at ``steps``: the first tick at or after
    the end of entry ``after`` (executed entries) and before the end of entry ``before`` (sent)
    where the job's tick record is at ``steps`` (``after`` when none is); a move whose rest
    takes no step counts as executed."""
    ends = entry_end_ticks(job)
    lo = int(ends[after - 1]) if after > 0 else 0
    hi = int(ends[min(before, len(ends)) - 1]) if before > 0 else 0
    window = job.ticks[lo:hi]
    hits = np.flatnonzero((window == np.asarray(steps)).all(axis=1))
    if not len(hits):
        return after
    tick = lo + int(hits[0]) + 1  # ticks done
    done = int(np.searchsorted(ends, tick, side="left"))  # entries ended before that tick
    if done < len(ends) and job.entries[done].move is not None:
        # The move under way counts as done when the rest of it stays where the motors are
        # (no step left to take); a pen move after it does not (ES flushed it).
        rest = job.ticks[tick - 1 : int(ends[done])]
        done += bool((rest == np.asarray(steps)).all())
    return max(after, done)


def entry_end_ticks(job: Job) -> np.ndarray:
    """Per entry: the motion ticks done once it has executed."""
    ticks = [round(e.duration * TICK_HZ) if e.move is not None else 0 for e in job.entries]
    return np.cumsum(np.asarray(ticks, dtype=np.int64))


def _name(line: bytes) -> str:
    return line.split(b",")[0].strip().decode("ascii", "replace")
