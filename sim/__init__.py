"""Simulated devices for testing tagbot without hardware.

Simulators stand in for a Grbl pen plotter and for DYNAMIXEL servo arms, speaking the wire
protocols defined in ``firmware_protocols`` (for example over pseudo-terminals). They must not
import ``tagbot``: they see the host only through the protocol, as real hardware would.
"""
