"""Small tags, fast arm profiles and a simulated chain that records what the servos receive."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import pytest

from sim.dynamixel import SimulatedChain, SimulatedServo, attach_chain, detach_chain
from tagbot.arm import ArmProfile, load_profile
from tagbot.arm.run import simulated_chain
from tagbot.model import Plan, Tag

FAST = [
    "motion.travel_speed=400",
    "shoulder.max_speed=270",
    "elbow.max_speed=270",
    "shoulder.max_acceleration=6000",
    "elbow.max_acceleration=6000",
    "pen.move_time=0.05",
    "place.scale=8",
]
"""Overrides that keep real-time runs short: quick travel and pen moves."""

GOAL_POSITION = 116
TORQUE_ENABLE = 64


def small_tag(length: float = 10.0) -> Tag:
    """One plan: a hook, two strokes."""
    plan = Plan(
        targets=[[0.0, 0.0], [length, 0.0], [length, 0.6 * length]],
        dt=[0.0, 0.15],
        mu=[math.log(0.2)] * 2,
        sigma=[0.3, 0.3],
        phi1=[0.3, 0.0],
        phi2=[0.0, -0.3],
    )
    return Tag(plans=(plan,))


def hook_from_its_end() -> Tag:
    """The hook drawn from its bottom-right end: 10 units left, then 6 up."""
    plan = Plan(
        targets=[[10.0, 0.0], [0.0, 0.0], [0.0, 6.0]],
        dt=[0.0, 0.15],
        mu=[math.log(0.2)] * 2,
        sigma=[0.3, 0.3],
        phi1=[0.3, 0.0],
        phi2=[0.0, -0.3],
    )
    return Tag(plans=(plan,))


def two_plan_tag() -> Tag:
    """Two plans with a pen lift between them."""
    first = small_tag().plans[0]
    second = Plan(
        targets=[[0.0, 8.0], [6.0, 10.0]],
        dt=[0.0],
        mu=[math.log(0.2)],
        sigma=[0.3],
        phi1=[0.0],
        phi2=[0.0],
        start=first.end(15.0) + 0.3,
    )
    return Tag(plans=(first, second))


@dataclass
class Recorded:
    """What one simulated chain received, seen from the servos: ``(t, id, address, value)``."""

    chain: SimulatedChain
    name: str
    url: str
    writes: list[tuple[float, int, int, int]] = field(default_factory=list)

    def values(self, id: int, address: int) -> list[int]:
        return [v for _, i, a, v in self.writes if i == id and a == address]

    def servo(self, id: int) -> SimulatedServo:
        return self.chain.servo(id)


_names = itertools.count()


def recording(chain: SimulatedChain) -> Recorded:
    """Record every write ``chain``'s servos execute; a simulated-time chain is also attached for
    ``dxlsim://`` (``url``; a real-time one is for :func:`serve_pty`)."""
    name = f"armtest_{next(_names)}"
    url = attach_chain(chain, name) if chain.clock == "simulated" else ""
    record = Recorded(chain, name, url)
    for servo in chain.servos:
        original = servo.write

        def write(address: int, data: bytes, t: float, _orig=original, _id=servo.id) -> int:
            error = _orig(address, data, t)
            if not error:
                value = int.from_bytes(bytes(data), "little", signed=len(data) == 4)
                record.writes.append((t, _id, address, value))
            return error

        servo.write = write  # type: ignore[method-assign]
    return record


@pytest.fixture
def profile() -> ArmProfile:
    return load_profile()


@pytest.fixture
def record() -> Iterator[Callable[[SimulatedChain], Recorded]]:
    """``record(chain)``: attach and record a chain for the test, detached afterwards."""
    made: list[Recorded] = []

    def make(chain: SimulatedChain) -> Recorded:
        made.append(recording(chain))
        return made[-1]

    yield make
    for item in made:
        detach_chain(item.name)


@pytest.fixture
def sim(profile: ArmProfile, record: Callable[[SimulatedChain], Recorded]) -> Recorded:
    """A simulated chain for the default profile, recording, attached as ``sim.url``; its horns
    start at the servos' middle (2048 ticks: the elbow straight, outside its limits)."""
    return record(simulated_chain(profile, at_park=False))


def goals_path(n: int, profile: ArmProfile) -> np.ndarray:
    """``(n, 3)`` slow, smooth goals inside the default joint limits (pen up)."""
    k = np.arange(n)
    shoulder = 1024 + 1024 + np.rint(300 * np.sin(2 * np.pi * k / 5000)).astype(np.int64)
    elbow = 2048 + 1000 + np.rint(400 * np.sin(2 * np.pi * k / 7000)).astype(np.int64)
    pen = np.full(n, profile["pen.up"], dtype=np.int64)
    return np.column_stack([shoulder, elbow, pen])
