"""A strict simulated EiBotBoard (the AxiDraw's controller, firmware 3.x).

:class:`SimulatedEBB` (:mod:`sim.ebb.device`) parses and answers the EBB's serial commands and
executes their motion at the 25 kHz stepper tick with the firmware's arithmetic
(:mod:`firmware_protocols.ebb.motion`), recording it (:class:`Recorder`); :mod:`sim.ebb.transport`
connects it to hosts (the ``ebbsim://`` pyserial URL, a pseudo-terminal).
"""

from sim.ebb.device import DEFAULT_COMMAND_TIME, FIFO_MAX, SimulatedEBB
from sim.ebb.recorder import Recorder, Segment, Trace
from sim.ebb.servo import ServoSegment, servo_travel_time

__all__ = [
    "DEFAULT_COMMAND_TIME",
    "FIFO_MAX",
    "Recorder",
    "Segment",
    "ServoSegment",
    "SimulatedEBB",
    "Trace",
    "servo_travel_time",
]
