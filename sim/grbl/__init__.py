"""Simulated Grbl 1.1 motion: the look-ahead planner and the stepper's timing.

:class:`GrblExecutor` takes already-parsed motion blocks (:class:`MotionBlock`, :class:`Dwell`)
and executes them in simulated time as Grbl 1.1h's ``planner.c`` and ``stepper.c`` would, with
back-pressure (``submit`` refuses while the 15-block planner is full), feed hold, resume and
soft reset. The serial-device layer on top of it parses G-code and answers ``ok``:
:class:`SimulatedGrbl` (:mod:`sim.grbl.device`), a byte-level Grbl 1.1h; :mod:`sim.grbl.transport`
connects it to hosts (the ``grblsim://`` pyserial URL handler, a pseudo-terminal server).
"""

from sim.grbl.device import DEFAULT_SETTINGS, SimulatedGrbl
from sim.grbl.executor import (
    ACCELERATION_TICKS_PER_SECOND,
    DT_SEGMENT,
    HOLD,
    IDLE,
    RUN,
    SEGMENT_CAPACITY,
    GrblExecutor,
    Recorder,
)
from sim.grbl.planner import (
    BLOCK_BUFFER_SIZE,
    DWELL_TIME_STEP,
    PLANNER_CAPACITY,
    Dwell,
    GrblPlanner,
    GrblSettings,
    MotionBlock,
    PlanBlock,
)

__all__ = [
    "ACCELERATION_TICKS_PER_SECOND",
    "BLOCK_BUFFER_SIZE",
    "DEFAULT_SETTINGS",
    "DT_SEGMENT",
    "DWELL_TIME_STEP",
    "HOLD",
    "IDLE",
    "PLANNER_CAPACITY",
    "RUN",
    "SEGMENT_CAPACITY",
    "Dwell",
    "GrblExecutor",
    "GrblPlanner",
    "GrblSettings",
    "MotionBlock",
    "PlanBlock",
    "Recorder",
    "SimulatedGrbl",
]
