"""Simulated devices for testing tagbot without hardware.

Simulators stand in for a Grbl pen plotter and for DYNAMIXEL servo arms, speaking the wire
protocols defined in ``firmware_protocols`` (for example over pseudo-terminals). They must not
import ``tagbot``: they see the host only through the protocol, as real hardware would.

- :mod:`sim.grbl`: Grbl 1.1h (``grblsim://`` URLs, pty server);
- :mod:`sim.dynamixel`: a chain of DYNAMIXEL X-series servos, Protocol 2.0 device side
  (``dxlsim://`` URLs with a simulated ``port.clock``, pty server for the unmodified
  dynamixel-sdk, fault hooks, joint and pen-tip recorder).
"""
