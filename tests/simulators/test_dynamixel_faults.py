"""SimulatedChain.set_reply_faults: status packets late (in order) or lost, like a real line."""

from __future__ import annotations

import pytest

from firmware_protocols.dynamixel import (
    InstructionPacket,
    PacketDecoder,
    StatusPacket,
    encode_instruction,
)
from sim.dynamixel import SimulatedChain

BYTE = 10e-6  # one byte at 1 Mbit/s
STATUS_4 = 15  # bytes of a status packet with 4 bytes of data


@pytest.fixture
def chain() -> SimulatedChain:
    return SimulatedChain({1: "XL430-W250", 2: "XL430-W250", 3: "XM430-W350"})


def _sync_read(chain: SimulatedChain) -> float:
    """Send a SYNC_READ of Present Position to 1, 2, 3; when it has reached the servos."""
    chain.write(encode_instruction(InstructionPacket.sync_read(132, 4, [1, 2, 3])))
    end = chain.next_input_event()
    assert end is not None
    return end


class _Host:
    """The host's side: status packets decoded as their bytes come (IDs, in order)."""

    def __init__(self) -> None:
        self.decoder = PacketDecoder()

    def __call__(self, data: bytes) -> list[int]:
        packets = self.decoder.feed(data)
        assert all(isinstance(p, StatusPacket) for p in packets), packets
        return [p.id for p in packets]  # type: ignore[union-attr]


def test_latency_delays_every_reply_and_keeps_the_bus_timing(chain) -> None:
    chain.set_reply_faults(latency=0.05)
    _replies = _Host()
    end = _sync_read(chain)
    chain.advance_to(end)
    delay = chain.servo(1).return_delay  # the factory's 500 µs
    # Nothing reaches the host before the latency; then the three replies as on the bus.
    assert chain.ready_time(1) == pytest.approx(end + delay + 0.05 + BYTE, abs=1e-9)
    chain.advance_to(end + 0.05)
    assert chain.read() == b""
    chain.advance_to(end + 0.05 + 3 * (delay + STATUS_4 * BYTE) + 1e-9)
    assert _replies(chain.read()) == [1, 2, 3]


def test_jitter_keeps_replies_in_order(chain) -> None:
    chain.set_reply_faults(latency=0.002, jitter=0.03, seed=1)
    _replies = _Host()
    got: list[int] = []
    for _ in range(20):
        _sync_read(chain)
        chain.advance(0.001)
        got += _replies(chain.read())
    chain.advance(0.1)
    got += _replies(chain.read())
    assert got == [1, 2, 3] * 20


def test_drop_loses_replies_but_the_servos_execute(chain) -> None:
    chain.set_reply_faults(drop=0.3, seed=7)
    _replies = _Host()
    got: list[int] = []
    for _ in range(50):
        _sync_read(chain)
        chain.advance(0.002)
        got += _replies(chain.read())
    chain.advance(0.01)
    got += _replies(chain.read())
    assert 0 < chain.replies_dropped < 100 and len(got) == 150 - chain.replies_dropped
    # Writes are still executed when their status is lost.
    chain.set_reply_faults(drop=1.0)
    chain.write(encode_instruction(InstructionPacket.write(2, 65, bytes([1]))))  # LED on
    chain.advance(0.01)
    assert chain.read() == b"" and chain.servo(2).get("led") == 1


def test_same_seed_same_faults_and_zero_is_a_clean_line() -> None:
    def run(seed: int) -> list[int]:
        chain = SimulatedChain({1: "XL430-W250", 2: "XL430-W250", 3: "XL430-W250"})
        chain.set_reply_faults(drop=0.5, seed=seed)
        _replies = _Host()
        got: list[int] = []
        for _ in range(10):
            _sync_read(chain)
            chain.advance(0.002)
            got += _replies(chain.read())
        return got

    assert run(4) == run(4) != run(5)
    chain = SimulatedChain({1: "XL430-W250"})
    chain.set_reply_faults(latency=0.1, drop=1.0)
    chain.set_reply_faults()
    chain.write(encode_instruction(InstructionPacket.ping(1)))
    chain.advance(0.001)
    assert _Host()(chain.read()) == [1]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"latency": -0.1}, "latency"),
        ({"jitter": float("nan")}, "jitter"),
        ({"drop": 1.5}, "drop"),
    ],
)
def test_bad_fault_settings_are_refused(chain, kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        chain.set_reply_faults(**kwargs)
