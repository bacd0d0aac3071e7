"""dynamixel-sdk 4.1.0 as an independent oracle for the Protocol 2.0 layer.

The SDK's PacketHandler and group classes run against a fake port that records what they write
and serves replies encoded here. Every instruction the SDK builds must equal ours byte for byte
(CRC included; the SDK does not stuff, so ours is encoded unstuffed where that matters), our
decoder must read what the SDK writes, and the SDK must accept the status packets we encode,
stuffed ones included.
"""

from __future__ import annotations

import dynamixel_sdk
import pytest
from dynamixel_sdk import protocol2_packet_handler as sdk_protocol
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.dynamixel import (
    BROADCAST_ID,
    ERROR_ALERT,
    ErrorCode,
    Instruction,
    InstructionPacket,
    PacketDecoder,
    StatusPacket,
    decode_packet,
    encode_instruction,
    encode_status,
    unstuff,
)

SUCCESS = dynamixel_sdk.COMM_SUCCESS


class FakePort:
    """Duck-typed ``dynamixel_sdk.PortHandler``: records writes, serves queued reply bytes."""

    def __init__(self, reply: bytes = b"") -> None:
        self.is_using = False
        self.written: list[bytes] = []
        self.rx = bytearray(reply)

    def clearPort(self) -> None:  # the SDK's method names
        pass  # the real one drops unread input; the reply is queued before the request here

    def writePort(self, packet) -> int:
        self.written.append(bytes(packet))
        return len(packet)

    def readPort(self, length: int) -> bytes:
        chunk = bytes(self.rx[:length])
        del self.rx[:length]
        return chunk

    def setPacketTimeout(self, packet_length: int) -> None:
        pass

    def setPacketTimeoutMillis(self, msec: float) -> None:
        pass

    def isPacketTimeout(self) -> bool:
        return True  # asked only when the queued bytes ran out

    def getBaudRate(self) -> int:
        return 1_000_000


def handler():
    return dynamixel_sdk.PacketHandler(2.0)


def u32(value: int) -> bytes:
    return value.to_bytes(4, "little")


def only_write(port: FakePort) -> bytes:
    assert len(port.written) == 1
    return port.written[0]


def test_constants_agree_with_the_sdk() -> None:
    for member in Instruction:
        name = "INST_STATUS" if member is Instruction.STATUS else f"INST_{member.name}"
        assert getattr(dynamixel_sdk, name) == member, name
    assert dynamixel_sdk.BROADCAST_ID == BROADCAST_ID
    assert dynamixel_sdk.MAX_ID == 252
    assert sdk_protocol.ERRBIT_ALERT == ERROR_ALERT
    for code in ErrorCode:
        assert getattr(sdk_protocol, f"ERRNUM_{code.name}") == code


def test_ping() -> None:
    port = FakePort(encode_status(StatusPacket.ping_reply(1, 1060, 45)))
    assert handler().ping(port, 1) == (1060, SUCCESS, 0)
    assert only_write(port) == encode_instruction(InstructionPacket.ping(1))


def test_read() -> None:
    port = FakePort(encode_status(StatusPacket(1, 0, u32(166))))
    data, result, error = handler().readTxRx(port, 1, 132, 4)
    assert (bytes(data), result, error) == (u32(166), SUCCESS, 0)
    assert only_write(port) == encode_instruction(InstructionPacket.read(1, 132, 4))


@given(
    st.integers(0, 252),
    st.binary(max_size=8).map(lambda b: bytes(x % 0xFD for x in b)),
    st.binary(max_size=8).map(lambda b: bytes(x % 0xFD for x in b)),
)
def test_sdk_reads_our_stuffed_status(id: int, before: bytes, after: bytes) -> None:
    # Data holding the header pattern once: we send it stuffed, the SDK must read it back.
    data = before + b"\xff\xff\xfd" + after
    port = FakePort(encode_status(StatusPacket(id, 0, data)))
    assert handler().readTxRx(port, id, 0, len(data)) == (list(data), SUCCESS, 0)


def test_overlapping_pattern_is_unstuffed_correctly() -> None:
    # Data FF FF FD FF FD FD is stuffed once: FF FF FD FD FF FD FD. dynamixel-sdk 4.1.0 is no
    # oracle here: its removeStuffing works in place and then matches FF FF FD FD against bytes
    # it has already shifted, so it drops the last real FD (and reads a CRC byte as data).
    data = bytes.fromhex("FF FF FD FF FD FD")
    frame = encode_status(StatusPacket(1, 0, data))
    assert frame[9:16] == bytes.fromhex("FF FF FD FD FF FD FD")
    assert decode_packet(frame) == StatusPacket(1, 0, data)


def test_write_and_device_errors() -> None:
    for error in (0, ErrorCode.ACCESS, ERROR_ALERT, ERROR_ALERT | ErrorCode.DATA_LIMIT):
        port = FakePort(encode_status(StatusPacket(1, error)))
        assert handler().write4ByteTxRx(port, 1, 116, 512) == (SUCCESS, error)
        assert only_write(port) == encode_instruction(InstructionPacket.write(1, 116, u32(512)))


@pytest.mark.parametrize(
    ("call", "ours"),
    [
        (lambda ph, port: ph.regWriteTxRx(port, 1, 104, 4, list(u32(200))),
         InstructionPacket.reg_write(1, 104, u32(200))),
        (lambda ph, port: ph.action(port, 1), InstructionPacket.action(1)),
        (lambda ph, port: ph.action(port, BROADCAST_ID), InstructionPacket.action()),
        (lambda ph, port: ph.reboot(port, 1), InstructionPacket.reboot(1)),
        (lambda ph, port: ph.factoryReset(port, 1, 0x01), InstructionPacket.factory_reset(1, 1)),
        (lambda ph, port: ph.factoryReset(port, 2, 0xFF), InstructionPacket.factory_reset(2, 0xFF)),
        (lambda ph, port: ph.clearMultiTurn(port, 1), InstructionPacket.clear_multi_turn(1)),
        (lambda ph, port: ph.write1ByteTxOnly(port, BROADCAST_ID, 64, 1),
         InstructionPacket.write(BROADCAST_ID, 64, b"\x01")),
        (lambda ph, port: ph.write2ByteTxOnly(port, 3, 100, 0xFF9C),
         InstructionPacket.write(3, 100, (-100).to_bytes(2, "little", signed=True))),
    ],
)  # fmt: skip
def test_other_instructions(call, ours: InstructionPacket) -> None:
    port = FakePort(encode_status(StatusPacket(ours.id)) if ours.id != BROADCAST_ID else b"")
    call(handler(), port)
    assert only_write(port) == encode_instruction(ours)
    assert decode_packet(only_write(port)) == ours


def test_group_sync_write() -> None:
    port, ph = FakePort(), handler()
    group = dynamixel_sdk.GroupSyncWrite(port, ph, 116, 4)
    for id, goal in ((1, 150), (2, 170), (3, 4095)):
        assert group.addParam(id, list(u32(goal)))
    assert group.txPacket() == SUCCESS
    ours = InstructionPacket.sync_write(116, 4, {1: u32(150), 2: u32(170), 3: u32(4095)})
    assert only_write(port) == encode_instruction(ours)
    assert len(only_write(port)) == 14 + 5 * 3  # the DESIGN note's 14 + 5N


def test_group_sync_read() -> None:
    replies = encode_status(StatusPacket(1, 0, u32(166))) + encode_status(
        StatusPacket(2, 0, u32(2079))
    )
    port, ph = FakePort(replies), handler()
    group = dynamixel_sdk.GroupSyncRead(port, ph, 132, 4)
    assert group.addParam(1) and group.addParam(2)
    assert group.txRxPacket() == SUCCESS
    assert group.getData(1, 132, 4) == 166
    assert group.getData(2, 132, 4) == 2079
    assert only_write(port) == encode_instruction(InstructionPacket.sync_read(132, 4, [1, 2]))


def test_group_fast_sync_read_request() -> None:
    port, ph = FakePort(), handler()
    group = dynamixel_sdk.GroupSyncRead(port, ph, 132, 4)
    assert group.addParam(5) and group.addParam(7)
    assert group.fastSyncReadTxPacket() == SUCCESS
    ours = InstructionPacket.fast_sync_read(132, 4, [5, 7])
    assert only_write(port) == encode_instruction(ours)


def test_group_bulk_read() -> None:
    replies = encode_status(StatusPacket(1, 0, b"\x77\x00")) + encode_status(
        StatusPacket(2, 0, b"\x24")
    )
    port, ph = FakePort(replies), handler()
    group = dynamixel_sdk.GroupBulkRead(port, ph)
    assert group.addParam(1, 144, 2) and group.addParam(2, 146, 1)
    assert group.txRxPacket() == SUCCESS
    assert (group.getData(1, 144, 2), group.getData(2, 146, 1)) == (119, 36)
    ours = InstructionPacket.bulk_read([(1, 144, 2), (2, 146, 1)])
    assert only_write(port) == encode_instruction(ours)


def test_group_bulk_write() -> None:
    port, ph = FakePort(), handler()
    group = dynamixel_sdk.GroupBulkWrite(port, ph)
    assert group.addParam(1, 32, 2, [0xA0, 0x00]) and group.addParam(2, 31, 1, [0x50])
    assert group.txPacket() == SUCCESS
    ours = InstructionPacket.bulk_write([(1, 32, b"\xa0\x00"), (2, 31, b"\x50")])
    assert only_write(port) == encode_instruction(ours)


payload_bytes = st.lists(st.sampled_from([0xFF, 0xFD, 0x00]) | st.integers(0, 255), max_size=16)


@given(st.integers(0, 252) | st.just(BROADCAST_ID), st.integers(0, 0xFFFF), payload_bytes)
def test_sdk_writes_are_ours_unstuffed(id: int, address: int, values: list[int]) -> None:
    data = bytes(values) or b"\x00"
    port = FakePort()
    handler().writeTxOnly(port, id, address, len(data), list(data))
    packet = InstructionPacket.write(id, address, data)
    assert only_write(port) == encode_instruction(packet, stuffing=False)
    # The decoder reads what the SDK meant, except in the one ambiguous case: unstuffed data
    # holding FF FF FD FD reads as stuffed FF FF FD, as a real device would read it too.
    (decoded,) = PacketDecoder().feed(only_write(port))
    if b"\xff\xff\xfd\xfd" in packet.params:
        assert decoded == InstructionPacket(id, Instruction.WRITE, unstuff(packet.params))
    else:
        assert decoded == packet


@given(st.dictionaries(st.integers(0, 252), st.integers(0, 2**32 - 1), min_size=1, max_size=8))
def test_sdk_sync_writes_are_ours(goals: dict[int, int]) -> None:
    port, ph = FakePort(), handler()
    group = dynamixel_sdk.GroupSyncWrite(port, ph, 116, 4)
    for id, goal in goals.items():
        group.addParam(id, list(u32(goal)))
    group.txPacket()
    ours = InstructionPacket.sync_write(116, 4, {id: u32(goal) for id, goal in goals.items()})
    assert only_write(port) == encode_instruction(ours, stuffing=False)
    assert decode_packet(only_write(port)) == ours
