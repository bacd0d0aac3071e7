"""Transports for :class:`~sim.dynamixel.chain.SimulatedChain`: a pyserial URL handler and a pty.

**In-process, simulated time** (fast tests): importing :mod:`sim.dynamixel` (or calling
:func:`register`) adds ``sim.dynamixel`` to ``serial.protocol_handler_packages``, so that::

    port = serial.serial_for_url("dxlsim://?ids=1,2,3&models=XL430-W250&baud=1000000", timeout=0)

returns a :class:`~sim.dynamixel.protocol_dxlsim.Serial` talking to a new chain (``port.chain``).
Query options: ``ids`` (comma-separated, required), ``models`` (one name or number for all, or
one per ID; default XL430-W250), ``baud`` (bus speed, default 1000000). ``dxlsim://<name>``
opens a chain given to :func:`attach_chain` instead, so a test can set it up first; it stays
attached (several opens see the same chain) until :func:`detach_chain`. The port's own
``baudrate`` is ignored, as on a pty: the bus runs at the chain's ``baud``.

The clock contract: ``port.clock.now()`` is the chain's simulated time in seconds and
``port.clock.sleep_until(t)`` runs the bus and the servos to time ``t`` without waiting on the
wall clock (so a host can pace 100,000 ticks faster than real time). Reads move the clock too:

- ``in_waiting`` counts the bytes that have arrived; when there are none it moves the clock by
  at most :data:`POLL_QUANTUM` towards the next event (a host polling it between its own
  deadlines is not carried past them);
- a read that finds its bytes waiting returns them at once;
- a non-blocking read (``timeout=0``, what dynamixel-sdk uses) that finds nothing moves the clock
  to when the bytes asked for (or the last ones on their way) will have arrived, or when the
  packet in flight reaches the servos; with nothing on its way, by :data:`POLL_QUANTUM` — so a
  host polling until a deadline on ``port.clock`` (or dynamixel-sdk's packet timeout, given a
  ``getCurrentTime`` on that clock) reaches it;
- a read with a timeout waits up to that many *simulated* seconds; ``timeout=None`` returns
  early when nothing more can arrive, rather than hang.

**Pseudo-terminal, real time** (any program, e.g. the unmodified ``dynamixel_sdk.PortHandler``):
:func:`serve_pty` opens ``os.openpty()`` in raw mode and runs one thread that pumps bytes between
the master side and a ``clock="real"`` chain. A pty ignores the baud rate dynamixel-sdk's
``setBaudRate`` sets; timing follows the chain's ``baud``.

The Grbl transports (:mod:`sim.grbl.transport`) are written against ``SimulatedGrbl`` (its
``read_timed``, ``busy``, ``silent``, ``on_close``), so this module has its own small ones; the
bus timing that Grbl's ``Link`` models lives in the chain here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from urllib.parse import parse_qsl, urlsplit

import serial

from sim import pty
from sim.dynamixel.chain import SimulatedChain
from sim.serial_port import Attached

POLL_QUANTUM = 50e-6
"""Simulated seconds an empty read moves the clock by when nothing is on its way (5 bytes at
1 Mbit/s)."""

_attached: Attached[SimulatedChain] = Attached("sim.dynamixel", "dxlsim")


def register() -> None:
    """Make ``serial.serial_for_url`` know the ``dxlsim://`` scheme (idempotent)."""
    _attached.register()


def attach_chain(chain: SimulatedChain, name: str) -> str:
    """Make ``chain`` the one ``dxlsim://<name>`` opens; returns that URL."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"name: must be an identifier, got {name!r}")
    if not isinstance(chain, SimulatedChain):
        raise TypeError(f"chain: expected SimulatedChain, got {chain!r}")
    if chain.clock != "simulated":
        raise ValueError("chain: dxlsim:// needs clock='simulated'; serve_pty() serves real time")
    return _attached.attach(chain, name)


def detach_chain(name: str) -> SimulatedChain | None:
    """Forget the chain attached as ``name`` (returns it, or None)."""
    return _attached.take(name)


def chain_from_url(url: str) -> SimulatedChain:
    """The chain a ``dxlsim://`` URL names or describes (``serial.SerialException`` if bad)."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "dxlsim":
        raise serial.SerialException(f"expected a dxlsim:// URL, got {url!r}")
    try:
        options = dict(parse_qsl(parts.query, keep_blank_values=True, strict_parsing=False))
        if parts.netloc:
            if options:
                raise ValueError("options only apply to a new chain")
            chain = _attached.get(parts.netloc)
            if chain is None:
                raise ValueError(f"no chain attached as {parts.netloc!r}")
            return chain
        unknown = set(options) - {"ids", "models", "baud"}
        if unknown:
            raise ValueError(f"unknown option {sorted(unknown)[0]!r}")
        if not options.get("ids"):
            raise ValueError("ids: give the servo IDs, e.g. ?ids=1,2,3")
        ids = [int(text) for text in options["ids"].split(",")]
        models: list[int | str] = [
            int(m) if m.strip().isdigit() else m.strip()
            for m in options.get("models", "XL430-W250").split(",")
        ]
        if len(models) == 1:
            models *= len(ids)
        if len(models) != len(ids):
            raise ValueError(f"models: give one model or {len(ids)}, got {len(models)}")
        if len(set(ids)) != len(ids):
            raise ValueError("ids: an ID is given twice")
        baud = int(options.get("baud", 1_000_000))
        return SimulatedChain(dict(zip(ids, models, strict=True)), baud)
    except ValueError as exc:
        raise serial.SerialException(f"{url}: {exc}") from exc


class BusClock:
    """The clock a ``dxlsim://`` port exposes as ``port.clock``."""

    def __init__(self, chain: SimulatedChain) -> None:
        self.chain = chain

    def now(self) -> float:
        """The chain's time in seconds."""
        return self.chain.now()

    def sleep_until(self, t: float) -> None:
        """Run the bus and the servos to time ``t`` (no effect if it has passed)."""
        self.chain.advance_to(t)


def wait_step(chain: SimulatedChain, size: int, deadline: float = math.inf) -> None:
    """Move ``chain``'s clock towards ``size`` more bytes for the host, bounded by ``deadline``:
    to when they (or the last ones on their way) arrive, or the packet in flight completes;
    by :data:`POLL_QUANTUM` when nothing is on its way."""
    now = chain.now()
    events = [
        e for e in (chain.ready_time(size), chain.next_input_event()) if e is not None and e > now
    ]
    target = min(events) if events else now + POLL_QUANTUM
    chain.advance_to(min(target, deadline))


class PtyServer(pty.PtyServer):
    """The pump behind :func:`serve_pty`; ``stop()`` ends it and closes the pseudo-terminal."""

    name = "dxlsim-pty"

    def __init__(self, chain: SimulatedChain, max_wait: float = 0.005) -> None:
        if chain.clock != "real":
            raise ValueError("chain: serve_pty needs a chain with clock='real'")
        self.chain = chain
        self.max_wait = max_wait
        super().__init__()

    def wait_time(self) -> float:
        """Until the chain's next event (a reply due), at most ``max_wait``."""
        with self.chain.lock:
            upcoming = self.chain.next_event()
            wait = self.max_wait if upcoming is None else upcoming - self.chain.now()
        return min(max(wait, 0.0), self.max_wait)

    def exchange(self, data: bytes) -> bytes | None:
        with self.chain.lock:
            if data:
                self.chain.write(data)
            return self.chain.read()


def serve_pty(chain: SimulatedChain) -> tuple[str, Callable[[], None]]:
    """Serve ``chain`` (``clock="real"``) on a new raw pseudo-terminal: ``(slave path, stop)``."""
    server = PtyServer(chain)
    return server.path, server.stop


register()

__all__ = [
    "POLL_QUANTUM",
    "BusClock",
    "PtyServer",
    "attach_chain",
    "chain_from_url",
    "detach_chain",
    "register",
    "serve_pty",
    "wait_step",
]
