"""The simulated DYNAMIXEL chain at the byte level: protocol rules, timing, motion, faults.

Golden packets are the worked examples of the ROBOTIS e-Manual's Protocol 2.0 page; the rest is
checked with the shared protocol layer (``firmware_protocols.dynamixel``) as the host side.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocols.dynamixel import (
    BROADCAST_ID,
    DecodeError,
    ErrorCode,
    InstructionPacket,
    PacketDecoder,
    StatusPacket,
    encode_instruction,
)
from sim.dynamixel import ArmGeometry, SimulatedChain
from sim.dynamixel.servo import (
    IN_POSITION,
    PROFILE_ONGOING,
    PROFILE_TRAPEZOIDAL,
    TICKS_PER_S2_PER_ACCELERATION_UNIT,
    TICKS_PER_S_PER_VELOCITY_UNIT,
    Trajectory,
    plan_time_based,
    plan_velocity_based,
)

BYTE = 10e-6  # one byte at 1 Mbit/s
VLIMIT_XL430 = 265 * TICKS_PER_S_PER_VELOCITY_UNIT  # default Velocity Limit, ticks/s


def u32(value: int) -> bytes:
    return value.to_bytes(4, "little", signed=value < 0)


def exchange(
    chain: SimulatedChain, packet: InstructionPacket, *, wait: float = 0.01, stuffing: bool = True
) -> list[StatusPacket | DecodeError]:
    """Send ``packet``, let ``wait`` simulated seconds pass, decode what came back."""
    chain.write(encode_instruction(packet, stuffing=stuffing))
    chain.advance(wait)
    decoder = PacketDecoder()
    return decoder.feed(chain.read()) + decoder.flush()


def one(chain: SimulatedChain, packet: InstructionPacket, **kwargs) -> StatusPacket:
    replies = exchange(chain, packet, **kwargs)
    assert len(replies) == 1 and isinstance(replies[0], StatusPacket), replies
    return replies[0]


def write(chain: SimulatedChain, id: int, address: int, data: bytes) -> int:
    return one(chain, InstructionPacket.write(id, address, data)).error


def read_int(chain: SimulatedChain, id: int, address: int, size: int) -> int:
    reply = one(chain, InstructionPacket.read(id, address, size))
    assert reply.error & 0x7F == 0, reply
    return int.from_bytes(reply.params, "little", signed=size == 4)


@pytest.fixture
def chain() -> SimulatedChain:
    return SimulatedChain({1: "XL430-W250", 2: "XL430-W250", 3: "XM430-W350"})


# -- e-Manual golden packets -----------------------------------------------------------------


def test_emanual_ping_read_write_examples():
    chain = SimulatedChain({1: 1020}, firmware_version=38)
    chain.set_model_number(1, 1030)  # the e-Manual's XM430-W210
    chain.write(bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E"))
    chain.advance(0.01)
    assert chain.read() == bytes.fromhex("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")
    chain.set_position(1, 166)
    chain.write(bytes.fromhex("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"))
    chain.advance(0.01)
    assert chain.read() == bytes.fromhex("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0")
    chain.write(bytes.fromhex("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"))
    chain.advance(0.01)
    assert chain.read() == bytes.fromhex("FF FF FD 00 01 04 00 55 00 A1 0C")
    assert chain.servo(1).get("goal_position") == 512


def test_emanual_sync_bulk_and_fast_sync_read_examples():
    chain = SimulatedChain({1: 1020, 2: 1020})
    chain.set_position(1, 166)
    chain.set_position(2, 2079)
    chain.write(bytes.fromhex("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA"))
    chain.advance(0.01)
    assert chain.read() == bytes.fromhex(
        "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE"
    )
    chain.servo(1).input_voltage = 119
    chain.servo(2).temperature = 36
    chain.write(bytes.fromhex("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05"))
    chain.advance(0.01)
    assert chain.read() == bytes.fromhex(
        "FF FF FD 00 01 06 00 55 00 77 00 C3 69FF FF FD 00 02 05 00 55 00 24 8B A9"
    )
    fast = SimulatedChain({3: 1020, 4: 1020, 7: 1020})
    for id, ticks in ((3, 166), (7, 2079), (4, 1023)):
        fast.set_position(id, ticks)
    fast.write(bytes.fromhex("FF FF FD 00 FE 0A 00 8A 84 00 04 00 03 07 04 20 F2"))
    fast.advance(0.01)
    assert fast.read() == bytes.fromhex(
        "FF FF FD 00 FE 19 00 55 00 03 A6 00 00 00 84 08"
        "00 07 1F 08 00 00 16 CA 00 04 FF 03 00 00 D1 9E"
    )


# -- control table rules -----------------------------------------------------------------------


def test_eeprom_is_locked_while_torque_is_on(chain):
    assert write(chain, 1, 9, b"\x00") == 0  # Return Delay Time, torque off
    assert write(chain, 1, 64, b"\x01") == 0
    assert write(chain, 1, 9, b"\x05") == ErrorCode.ACCESS
    assert write(chain, 1, 11, b"\x04") == ErrorCode.ACCESS  # Operating Mode
    assert read_int(chain, 1, 9, 1) == 0
    assert write(chain, 1, 65, b"\x01") == 0  # RAM stays writable
    assert write(chain, 1, 64, b"\x00") == 0
    assert write(chain, 1, 9, b"\x05") == 0


def test_access_length_range_and_limit_errors(chain):
    assert write(chain, 1, 132, u32(5)) == ErrorCode.ACCESS  # Present Position is read-only
    assert write(chain, 1, 0, b"\x00\x00") == ErrorCode.ACCESS  # Model Number
    assert write(chain, 1, 14, b"\x00") == ErrorCode.ACCESS  # no item there
    assert write(chain, 1, 116, b"\x00\x02") == ErrorCode.DATA_LENGTH  # half of Goal Position
    assert write(chain, 1, 11, b"\x02") == ErrorCode.DATA_RANGE  # no Operating Mode 2
    assert write(chain, 1, 11, b"\x00") == ErrorCode.DATA_RANGE  # XL430: no current mode
    assert write(chain, 3, 11, b"\x00") == 0  # XM430 has it
    assert write(chain, 1, 68, b"\x03") == ErrorCode.DATA_RANGE  # Status Return Level 0..2
    reply = one(chain, InstructionPacket.read(1, 140, 10))  # past the end of the table
    assert (reply.error, reply.params) == (ErrorCode.ACCESS, b"")
    # Position Control Mode: Goal Position within Min/Max Position Limit, else data limit error
    assert write(chain, 1, 48, u32(3000)) == 0  # Max Position Limit
    assert write(chain, 1, 64, b"\x01") == 0
    assert write(chain, 1, 116, u32(3001)) == ErrorCode.DATA_LIMIT
    assert write(chain, 1, 116, u32(-1)) == ErrorCode.DATA_LIMIT
    assert write(chain, 1, 116, u32(3000)) == 0
    assert write(chain, 1, 104, u32(266)) == ErrorCode.DATA_LIMIT  # Goal Velocity > limit 265
    # Extended Position Control Mode: only the ±1,048,575 range applies
    assert write(chain, 2, 11, b"\x04") == 0
    assert write(chain, 2, 64, b"\x01") == 0
    assert write(chain, 2, 116, u32(20_000)) == 0
    assert write(chain, 2, 116, u32(1_048_576)) == ErrorCode.DATA_RANGE
    # a multi-item write is all or nothing: Profile Acceleration, Velocity and Goal Position
    before = read_int(chain, 1, 108, 4)
    bad = u32(10) + u32(20) + u32(5000)
    assert write(chain, 1, 108, bad) == ErrorCode.DATA_LIMIT
    assert read_int(chain, 1, 108, 4) == before
    assert write(chain, 1, 108, u32(10) + u32(20) + u32(2500)) == 0
    assert read_int(chain, 1, 112, 4) == 20


def test_malformed_and_unknown_instructions(chain):
    assert one(chain, InstructionPacket(1, 0x50)).error == ErrorCode.INSTRUCTION
    assert one(chain, InstructionPacket(1, 0x02, b"\x84\x00\x04")).error == ErrorCode.DATA_LENGTH
    assert one(chain, InstructionPacket.action(1)).error == ErrorCode.INSTRUCTION  # nothing reg.
    assert exchange(chain, InstructionPacket.read(7, 132, 4)) == []  # no such servo


def test_hardware_error_sets_the_alert_bit_and_shuts_down(chain):
    assert write(chain, 1, 64, b"\x01") == 0
    chain.set_hardware_error(1, 0x20)  # overload, selected by the default Shutdown 0x34
    assert one(chain, InstructionPacket.ping(1)).error == 0x80
    reply = one(chain, InstructionPacket.read(1, 64, 1))
    assert (reply.error, reply.params) == (0x80, b"\x00")  # torque went off
    assert one(chain, InstructionPacket.read(1, 70, 1)).params == b"\x20"
    assert write(chain, 1, 64, b"\x01") == 0x80 | ErrorCode.RESULT_FAIL
    assert write(chain, 1, 65, b"\x01") == 0x80  # other writes work, with the alert
    assert one(chain, InstructionPacket.ping(2)).error == 0  # the others are fine
    # an error not selected by Shutdown raises the alert but keeps the torque
    assert write(chain, 2, 64, b"\x01") == 0
    chain.set_hardware_error(2, 0x08)
    assert one(chain, InstructionPacket.read(2, 64, 1)).params == b"\x01"
    assert one(chain, InstructionPacket.ping(2)).error == 0x80
    # REBOOT answers (still alerting), is deaf while booting, then comes back clean
    assert one(chain, InstructionPacket.reboot(1)).error == 0x80
    assert exchange(chain, InstructionPacket.ping(1), wait=0.01) == []
    chain.advance(chain.servo(1).boot_time)
    assert one(chain, InstructionPacket.ping(1)).error == 0
    assert write(chain, 1, 64, b"\x01") == 0


# -- bus behaviour -----------------------------------------------------------------------------


def test_broadcast_ping_answers_in_id_order_one_after_the_other():
    chain = SimulatedChain({5: "XL430-W250", 1: "XM430-W350", 3: "XL430-W250"})
    chain.write(encode_instruction(InstructionPacket.ping(BROADCAST_ID)))
    end = chain.next_input_event()
    assert end == pytest.approx(10 * BYTE)
    chain.advance(0.01)
    data = chain.read()
    replies = PacketDecoder().feed(data)
    assert [(r.id, r.params[:2]) for r in replies] == [
        (1, (1020).to_bytes(2, "little")),
        (3, (1060).to_bytes(2, "little")),
        (5, (1060).to_bytes(2, "little")),
    ]
    # each status starts Return Delay Time (500 µs) after the previous one has ended
    chain2 = SimulatedChain({5: "XL430-W250", 1: "XM430-W350", 3: "XL430-W250"})
    chain2.write(encode_instruction(InstructionPacket.ping(BROADCAST_ID)))
    starts = []
    t = end
    for _ in range(3):
        first = chain2.ready_time(1)
        while first is None or first <= t:
            chain2.advance_to(chain2.next_event())
            first = chain2.ready_time(1)
        starts.append(first - BYTE)
        chain2.advance_to(chain2.ready_time(14))
        assert len(chain2.read()) == 14
        t = chain2.now()
    assert np.allclose(np.diff([end, *starts]), [500e-6, 500e-6 + 14 * BYTE, 500e-6 + 14 * BYTE])


def test_only_ping_and_reads_answer_broadcast(chain):
    assert exchange(chain, InstructionPacket.write(BROADCAST_ID, 65, b"\x01")) == []
    assert all(chain.servo(i).get("led") == 1 for i in (1, 2, 3))
    assert exchange(chain, InstructionPacket(BROADCAST_ID, 0x02, b"\x84\x00\x04\x00")) == []
    sync = InstructionPacket.sync_write(65, 1, {1: b"\x00", 3: b"\x00"})
    assert exchange(chain, sync) == []
    assert [chain.servo(i).get("led") for i in (1, 2, 3)] == [0, 1, 0]
    bulk = InstructionPacket.bulk_write([(2, 65, b"\x00"), (3, 9, b"\x10")])
    assert exchange(chain, bulk) == []
    assert chain.servo(2).get("led") == 0 and chain.servo(3).get("return_delay_time") == 16
    replies = exchange(chain, InstructionPacket.bulk_read([(3, 9, 1), (1, 7, 1)]))
    assert [(r.id, r.params) for r in replies] == [(3, b"\x10"), (1, b"\x01")]


def test_stuffed_and_unstuffed_instructions_are_both_accepted(chain):
    value = -131073  # Goal Position bytes FF FF FD FF: the header pattern
    assert u32(value)[:3] == b"\xff\xff\xfd"
    assert write(chain, 1, 11, b"\x04") == 0  # Extended Position Control Mode
    assert write(chain, 1, 64, b"\x01") == 0
    packet = InstructionPacket.write(1, 116, u32(value))
    stuffed = encode_instruction(packet)
    unstuffed = encode_instruction(packet, stuffing=False)
    assert len(stuffed) == len(unstuffed) + 1
    for form in (stuffed, unstuffed):
        assert write(chain, 1, 116, u32(0)) == 0
        chain.write(form)
        chain.advance(0.01)
        assert PacketDecoder().feed(chain.read()) == [StatusPacket(1, 0)]
        assert read_int(chain, 1, 116, 4) == value


def test_return_delay_time_delays_the_reply(chain):
    for rdt in (0, 100, 250):
        assert write(chain, 2, 9, bytes([rdt])) == 0
        chain.write(encode_instruction(InstructionPacket.read(2, 132, 4)))
        end = chain.next_input_event()
        chain.advance_to(end)
        first_byte = chain.ready_time(1)
        assert first_byte - BYTE - end == pytest.approx(rdt * 2e-6, abs=1e-9)
        chain.advance(0.01)
        assert len(chain.read()) == 15


def test_status_return_level(chain):
    # the new level already decides about the status of the write that sets it
    assert exchange(chain, InstructionPacket.write(1, 68, b"\x01")) == []
    assert exchange(chain, InstructionPacket.write(1, 65, b"\x01")) == []
    assert chain.servo(1).get("led") == 1  # executed all the same
    assert read_int(chain, 1, 65, 1) == 1
    assert exchange(chain, InstructionPacket.write(1, 68, b"\x00")) == []
    assert exchange(chain, InstructionPacket.read(1, 65, 1)) == []
    assert exchange(chain, InstructionPacket.sync_read(65, 1, [1, 2])) == [
        StatusPacket(2, 0, b"\x00")
    ]
    assert one(chain, InstructionPacket.ping(1)).params[:2] == (1060).to_bytes(2, "little")


def test_reg_write_and_action(chain):
    for id in (1, 2):
        assert write(chain, id, 64, b"\x01") == 0
    assert exchange(chain, InstructionPacket.reg_write(BROADCAST_ID, 116, u32(3000))) == []
    assert read_int(chain, 1, 69, 1) == 1
    chain.advance(0.5)
    assert read_int(chain, 1, 116, 4) == 2048  # not applied yet
    assert exchange(chain, InstructionPacket.action()) == []
    chain.advance(1.0)
    assert [read_int(chain, id, 132, 4) for id in (1, 2)] == [3000, 3000]
    assert read_int(chain, 1, 69, 1) == 0
    assert one(chain, InstructionPacket.reg_write(1, 116, u32(9000))).error == ErrorCode.DATA_LIMIT


def test_factory_reset_options(chain):
    assert write(chain, 1, 9, b"\x00") == 0
    assert write(chain, 1, 7, b"\x09") == 0  # the status already carries the new ID
    assert exchange(chain, InstructionPacket.factory_reset(BROADCAST_ID, 0xFF)) == []
    chain.advance(0.2)
    assert read_int(chain, 9, 9, 1) == 0  # broadcast "reset all" was refused
    assert one(chain, InstructionPacket.factory_reset(9, 0x02)).id == 9
    chain.advance(0.2)
    assert read_int(chain, 9, 9, 1) == 250  # reset, but kept its ID and baud rate
    assert one(chain, InstructionPacket.factory_reset(9, 0x01)).error == 0
    chain.advance(0.2)
    assert chain.servo(9).baud_rate == 57_600  # now deaf to the 1 Mbit/s bus
    assert exchange(chain, InstructionPacket.ping(9)) == []


def test_clear_multi_turn(chain):
    assert write(chain, 1, 11, b"\x04") == 0
    assert write(chain, 1, 64, b"\x01") == 0
    assert write(chain, 1, 116, u32(4096 * 3 + 100)) == 0
    assert one(chain, InstructionPacket.clear_multi_turn(1)).error == ErrorCode.RESULT_FAIL
    chain.advance(5.0)
    assert one(chain, InstructionPacket.clear_multi_turn(1)).error == 0
    assert read_int(chain, 1, 132, 4) == 100


# -- faults and resynchronisation ----------------------------------------------------------------


def test_garbage_then_a_packet_is_answered(chain):
    chain.write(b"\x00\xff\x12noise\xff\xff")
    assert one(chain, InstructionPacket.ping(2)).id == 2


def test_bad_crc_gets_no_reply_unless_asked():
    frame = bytearray(encode_instruction(InstructionPacket.read(1, 132, 4)))
    frame[-1] ^= 0x55
    chain = SimulatedChain({1: "XL430-W250"})
    chain.write(bytes(frame))
    chain.advance(0.01)
    assert chain.read() == b""
    assert one(chain, InstructionPacket.ping(1)).error == 0  # and it resynchronised
    strict = SimulatedChain({1: "XL430-W250"}, reply_to_bad_crc=True)
    strict.write(bytes(frame))
    strict.advance(0.01)
    assert PacketDecoder().feed(strict.read()) == [StatusPacket(1, ErrorCode.CRC)]


def test_fault_hooks(chain):
    chain.silence(2)
    assert exchange(chain, InstructionPacket.write(2, 65, b"\x01")) == []
    assert chain.servo(2).get("led") == 1  # it heard and executed
    replies = exchange(chain, InstructionPacket.sync_read(7, 1, [1, 2, 3]))
    assert [r.id for r in replies] == [1, 3]
    chain.silence(2, on=False)
    assert one(chain, InstructionPacket.ping(2)).id == 2

    chain.corrupt_next(3, count=2)
    for _ in range(2):
        (bad,) = exchange(chain, InstructionPacket.ping(3))
        assert isinstance(bad, DecodeError) and bad.kind == DecodeError.BAD_CRC
    assert one(chain, InstructionPacket.ping(3)).id == 3

    chain.set_model_number(1, 1030)
    assert one(chain, InstructionPacket.ping(1)).params[:2] == (1030).to_bytes(2, "little")
    assert read_int(chain, 1, 0, 2) == 1030
    with pytest.raises(KeyError, match="no servo with ID 42"):
        chain.silence(42)


def test_constructor_checks():
    with pytest.raises(ValueError, match="baud"):
        SimulatedChain({1: "XL430-W250"}, baud=250_000)
    with pytest.raises(ValueError, match="model"):
        SimulatedChain({1: "AX-12"})
    with pytest.raises(ValueError, match="ID"):
        SimulatedChain({253: "XL430-W250"})
    with pytest.raises(ValueError, match="clock"):
        SimulatedChain({1: "XL430-W250"}, clock="fast")


# -- motion ------------------------------------------------------------------------------------


def goal_write_end(chain: SimulatedChain, id: int, goal: int) -> float:
    """Write Goal Position; returns when the instruction finished arriving."""
    chain.write(encode_instruction(InstructionPacket.write(id, 116, u32(goal))))
    end = chain.next_input_event()
    chain.advance(0.002)
    assert PacketDecoder().feed(chain.read()) == [StatusPacket(id, 0)]
    return end


def test_time_based_profile_reaches_the_goal_on_time(chain):
    assert write(chain, 1, 10, b"\x04") == 0  # Drive Mode: time-based profile
    assert write(chain, 1, 64, b"\x01") == 0
    assert write(chain, 1, 108, u32(200) + u32(1000)) == 0  # 200 ms ramps, 1 s in all
    start = goal_write_end(chain, 1, 3048)
    chain.advance_to(start + 0.5)
    assert read_int(chain, 1, 122, 1) == 1
    status = read_int(chain, 1, 123, 1)
    assert status & PROFILE_ONGOING and status & 0x30 == PROFILE_TRAPEZOIDAL
    chain.advance_to(start + 1.5)
    assert read_int(chain, 1, 122, 1) == 0
    assert read_int(chain, 1, 123, 1) & (IN_POSITION | PROFILE_ONGOING) == IN_POSITION
    t, p = chain.trace(1, dt=0.0001).T
    assert np.all(p[t >= start + 1.0] == 3048)  # there, and held, from the requested time
    assert np.all(p[t < start + 1.0 - 0.001] < 3048)  # not a millisecond earlier
    chain2 = SimulatedChain({1: "XL430-W250"})  # Moving drops within the same millisecond
    assert write(chain2, 1, 10, b"\x04") == 0
    assert write(chain2, 1, 64, b"\x01") == 0
    assert write(chain2, 1, 108, u32(200) + u32(1000)) == 0
    start = goal_write_end(chain2, 1, 3048)
    chain2.advance_to(start + 0.9995 - 15 * BYTE)  # the READ below takes 14 bytes to arrive
    assert read_int(chain2, 1, 122, 1) == 1
    chain2.advance_to(start + 1.0005 - 15 * BYTE)
    assert read_int(chain2, 1, 122, 1) == 0
    # trapezoid: cruise speed 1000 ticks / (1 s - 0.2 s), reached after the 200 ms ramp
    speed = np.gradient(p, t)
    cruising = (t > start + 0.25) & (t < start + 0.75)
    assert np.allclose(speed[cruising], 1000 / 0.8, rtol=1e-3)


def test_velocity_limit_caps_every_profile(chain):
    assert write(chain, 1, 64, b"\x01") == 0  # Profile Velocity 0: as fast as allowed
    start = goal_write_end(chain, 1, 4095)
    chain.advance_to(start + 0.2)
    assert read_int(chain, 1, 128, 4) == 265  # Present Velocity at the Velocity Limit
    chain.advance(1.0)
    t, p = chain.trace(1).T
    assert np.max(np.abs(np.diff(p) / np.diff(t))) <= VLIMIT_XL430 * (1 + 1e-9)
    arrived = t[np.argmax(p >= 4095 - 0.5)]
    assert arrived - start == pytest.approx(2047 / VLIMIT_XL430, abs=0.0011)
    # a time-based move too fast for the limit is stretched, never faster than the limit
    assert write(chain, 2, 10, b"\x04") == 0
    assert write(chain, 2, 44, u32(100)) == 0  # Velocity Limit 100 × 0.229 rev/min
    assert write(chain, 2, 64, b"\x01") == 0
    assert write(chain, 2, 108, u32(20) + u32(100)) == 0  # 2000 ticks in 100 ms: too fast
    start = goal_write_end(chain, 2, 48)
    chain.advance(2.0)
    t, p = chain.trace(2).T
    limit = 100 * TICKS_PER_S_PER_VELOCITY_UNIT
    assert np.max(np.abs(np.diff(p) / np.diff(t))) <= limit * (1 + 1e-9)
    assert t[np.argmax(p <= 48.5)] - start > 2000 / limit


def test_new_goal_mid_move_is_continuous(chain):
    assert write(chain, 1, 64, b"\x01") == 0
    assert write(chain, 1, 108, u32(40) + u32(150)) == 0  # velocity-based trapezoid
    goal_write_end(chain, 1, 4000)
    chain.advance(0.15)
    goal_write_end(chain, 1, 1000)  # reverse while moving fast
    chain.advance(0.1)
    goal_write_end(chain, 1, 1500)
    chain.advance(2.0)
    t, p = chain.trace(1, dt=0.0005).T
    v = np.diff(p) / np.diff(t)
    amax = 40 * TICKS_PER_S2_PER_ACCELERATION_UNIT
    vmax = 150 * TICKS_PER_S_PER_VELOCITY_UNIT
    assert np.max(np.abs(v)) <= vmax * (1 + 1e-9)
    assert np.max(np.abs(np.diff(v))) <= amax * 0.0005 * 1.01  # no velocity jump anywhere
    assert p[-1] == pytest.approx(1500)


def test_torque_on_holds_the_present_position(chain):
    chain.set_position(1, 1234)
    assert write(chain, 1, 64, b"\x01") == 0
    assert read_int(chain, 1, 116, 4) == 1234
    chain.advance(0.5)
    assert read_int(chain, 1, 132, 4) == 1234
    assert read_int(chain, 1, 123, 1) & IN_POSITION
    with pytest.raises(RuntimeError, match="torque"):
        chain.set_position(1, 0)


def test_velocity_mode_ramps_to_goal_velocity(chain):
    assert write(chain, 2, 11, b"\x01") == 0
    assert write(chain, 2, 64, b"\x01") == 0
    assert write(chain, 2, 108, u32(10)) == 0
    assert write(chain, 2, 104, u32(-100)) == 0
    chain.advance(1.0)
    assert read_int(chain, 2, 128, 4) == -100
    assert read_int(chain, 2, 122, 1) == 1


def test_velocity_based_ramp_time_is_the_emanuals():
    # e-Manual "What is the Profile": t1 = 64 · Profile Velocity / Profile Acceleration [ms]
    for pv, pa in ((100, 10), (50, 40), (300, 1)):
        vmax = pv * TICKS_PER_S_PER_VELOCITY_UNIT
        amax = pa * TICKS_PER_S2_PER_ACCELERATION_UNIT
        pieces, kind = plan_velocity_based(0.0, 0.0, 1e6, vmax, amax)
        assert kind == PROFILE_TRAPEZOIDAL
        assert pieces[0][0] * 1000 == pytest.approx(64 * pv / pa, rel=1e-3)


@settings(max_examples=200, deadline=None)
@given(
    p0=st.floats(-5000, 5000),
    v0=st.floats(-3000, 3000),
    goal=st.floats(-5000, 5000),
    vmax=st.floats(10, 4000),
    amax=st.floats(50, 1e5) | st.just(math.inf),
)
def test_velocity_plans_end_at_rest_on_the_goal(p0, v0, goal, vmax, amax):
    pieces, _ = plan_velocity_based(p0, v0, goal, vmax, amax)
    p, v = p0, v0
    for duration, start_v, a in pieces:
        assert duration > 0
        if math.isfinite(amax):
            assert start_v == pytest.approx(v, abs=1e-6 * (1 + abs(v)))  # continuous velocity
            assert abs(a) <= amax * (1 + 1e-9)
        else:
            assert abs(start_v) <= vmax * (1 + 1e-9)
        p += (start_v + 0.5 * a * duration) * duration
        v = start_v + a * duration
        if math.isfinite(amax) and abs(v0) <= vmax:
            assert abs(v) <= vmax * (1 + 1e-9)
    assert p == pytest.approx(goal, abs=1e-6 * (1 + abs(goal) + abs(p0)))
    if pieces and math.isfinite(amax):
        assert v == pytest.approx(0.0, abs=1e-6 * (1 + abs(v0) + vmax))


@settings(max_examples=200, deadline=None)
@given(
    p0=st.floats(0, 4095),
    v0=st.floats(-500, 500),
    goal=st.floats(0, 4095),
    total=st.floats(0.01, 5.0),
    ramp=st.floats(0.0, 3.0),
)
def test_time_plans_arrive_on_time_unless_too_fast(p0, v0, goal, total, ramp):
    vmax = 4000.0
    pieces, _ = plan_time_based(p0, v0, goal, total, ramp, vmax)
    trajectory = Trajectory(0.0, p0)
    trajectory.replan(0.0, p0, pieces, final_position=goal)
    p_end = sum((v + 0.5 * a * d) * d for d, v, a in pieces) + p0
    assert p_end == pytest.approx(goal, abs=1e-6 * 4096)
    cruise = (goal - p0 - v0 * min(ramp, total / 2) / 2) / (total - min(ramp, total / 2))
    if abs(cruise) <= vmax:
        assert trajectory.end == pytest.approx(total)


# -- recorder ----------------------------------------------------------------------------------


def test_trace_is_sampled_every_millisecond_to_now(chain):
    chain.advance(0.0125)
    t, p = chain.trace(3).T
    assert t[0] == 0 and t[-1] == pytest.approx(0.0125)
    assert np.all(np.diff(t) <= 0.001 + 1e-12)
    assert np.all(p == 2048)
    with pytest.raises(ValueError, match="dt"):
        chain.trace(3, dt=0)


def test_pen_trace_follows_the_forward_kinematics():
    chain = SimulatedChain({1: "XM430-W350", 2: "XM430-W350", 3: "XL430-W250"})
    geometry = ArmGeometry(
        shoulder_id=1,
        elbow_id=2,
        pen_id=3,
        l1_mm=120.0,
        l2_mm=80.0,
        pen_down_ticks=1800,
        pen_up_ticks=2300,
        base_xy=(10.0, -5.0),
        zero_ticks=(2048, 1024),
        sign=(1, -1),
    )
    with pytest.raises(RuntimeError, match="set_geometry"):
        chain.pen_trace()
    chain.set_geometry(geometry)
    chain.set_position(1, 2048 + 1024)  # shoulder +90°
    chain.set_position(2, 1024)  # elbow straight
    chain.set_position(3, 1900)  # nearer pen-down
    chain.advance(0.01)
    _, x, y, pen = chain.pen_trace()[-1]
    assert (x, y, pen) == pytest.approx((10.0, -5.0 + 200.0, 1.0))
    chain.set_position(2, 0)  # sign −1: elbow +90° relative to link 1
    chain.set_position(3, 2200)
    chain.advance(0.01)
    _, x, y, pen = chain.pen_trace()[-1]
    assert (x, y, pen) == pytest.approx((10.0 - 80.0, -5.0 + 120.0, 0.0))
    # sweeping the shoulder keeps the pen on a circle of radius l1 + l2 around the base
    chain.set_position(2, 1024)
    for id, value in ((1, b"\x01"), (2, b"\x01")):
        assert write(chain, id, 64, value) == 0
    goal_write_end(chain, 1, 1000)
    chain.advance(1.0)
    trace = chain.pen_trace()
    assert trace.shape[1] == 4 and np.all(np.diff(trace[:, 0]) <= 0.001 + 1e-12)
    moving = trace[:, 0] > chain.now() - 1.0
    radius = np.hypot(trace[moving, 1] - 10.0, trace[moving, 2] + 5.0)
    assert np.allclose(radius, 200.0)
    with pytest.raises(ValueError, match="distinct"):
        ArmGeometry(1, 1, 3, 100, 100, 0, 1)
