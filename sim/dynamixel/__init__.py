"""Simulated DYNAMIXEL X-series servo chains speaking Protocol 2.0 (the device side).

- :class:`SimulatedServo` (:mod:`.servo`): one XL430-W250 or XM430-W350 — control table, write
  rules and error codes, velocity- and time-based motion profiles;
- :class:`SimulatedChain` (:mod:`.chain`): servos on one bus at the byte level, with bus timing,
  Return Delay Time, Status Return Level, fault hooks (silence, corrupt or late and lost
  replies, hardware errors) and a recorder
  (:meth:`~SimulatedChain.trace`, :meth:`~SimulatedChain.pen_trace` with :class:`ArmGeometry`);
- :mod:`.transport`: the ``dxlsim://`` pyserial URL handler (simulated time, ``port.clock``) and
  :func:`serve_pty` (a raw pseudo-terminal served in real time, for the unmodified
  dynamixel-sdk). Importing this package registers the URL scheme.

Example::

    import serial
    import sim.dynamixel

    port = serial.serial_for_url("dxlsim://?ids=1,2,3&models=XL430-W250", timeout=0)
    port.chain.set_hardware_error(2, 0x20)  # overload on ID 2
    port.chain.set_reply_faults(latency=0.016, drop=0.02)  # a slow adapter on a noisy line
"""

from sim.dynamixel.chain import BITS_PER_BYTE, ArmGeometry, SimulatedChain
from sim.dynamixel.servo import DEFAULT_FIRMWARE_VERSION, SimulatedServo
from sim.dynamixel.transport import (
    POLL_QUANTUM,
    BusClock,
    PtyServer,
    attach_chain,
    chain_from_url,
    detach_chain,
    register,
    serve_pty,
)

__all__ = [
    "BITS_PER_BYTE",
    "DEFAULT_FIRMWARE_VERSION",
    "POLL_QUANTUM",
    "ArmGeometry",
    "BusClock",
    "PtyServer",
    "SimulatedChain",
    "SimulatedServo",
    "attach_chain",
    "chain_from_url",
    "detach_chain",
    "register",
    "serve_pty",
]
