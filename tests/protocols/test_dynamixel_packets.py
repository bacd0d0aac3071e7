"""Protocol 2.0 packets: golden vectors, builders, parameter parsers and the error byte.

The golden vectors are the e-Manual's worked examples (Protocol 2.0 page), checked byte for byte
against dynamixel-sdk 4.1.0's CRC; they are copied here as literals.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.dynamixel import (
    BROADCAST_ID,
    MAX_LENGTH,
    BulkRead,
    BulkWrite,
    DecodeError,
    ErrorCode,
    Instruction,
    InstructionPacket,
    ParameterError,
    PingReply,
    ReadParams,
    StatusPacket,
    SyncReadParams,
    SyncWriteParams,
    WriteParams,
    decode_packet,
    describe_error,
    encode_instruction,
    encode_packet,
    encode_status,
    parse_params,
    parse_ping_reply,
)


def u32(value: int) -> bytes:
    return value.to_bytes(4, "little")


GOLDEN = {
    "ping id1": ("FF FF FD 00 01 03 00 01 19 4E", InstructionPacket.ping(1)),
    "ping status": (
        "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
        StatusPacket.ping_reply(1, model_number=1030, firmware=38),
    ),
    "ping broadcast": ("FF FF FD 00 FE 03 00 01 31 42", InstructionPacket.ping(BROADCAST_ID)),
    "read": ("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15", InstructionPacket.read(1, 132, 4)),
    "read status": ("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0", StatusPacket(1, 0, u32(166))),
    "write": (
        "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
        InstructionPacket.write(1, 116, u32(512)),
    ),
    "write status": ("FF FF FD 00 01 04 00 55 00 A1 0C", StatusPacket(1)),
    "sync read": (
        "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
        InstructionPacket.sync_read(132, 4, [1, 2]),
    ),
    "sync write": (
        "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
        InstructionPacket.sync_write(116, 4, {1: u32(150), 2: u32(170)}),
    ),
    "bulk read": (
        "FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05",
        InstructionPacket.bulk_read([(1, 144, 2), (2, 146, 1)]),
    ),
    "bulk write": (
        "FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68",
        InstructionPacket.bulk_write([(1, 32, b"\xa0\x00"), (2, 31, b"\x50")]),
    ),
    "reboot": ("FF FF FD 00 01 03 00 08 2F 4E", InstructionPacket.reboot(1)),
    "action": ("FF FF FD 00 01 03 00 05 02 CE", InstructionPacket.action(1)),
    "factory reset": ("FF FF FD 00 01 04 00 06 01 A1 E6", InstructionPacket.factory_reset(1, 1)),
    "clear": (
        "FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC",
        InstructionPacket.clear_multi_turn(1),
    ),
    "stuffed write": (
        "FF FF FD 00 01 0A 00 03 74 00 FF FF FD FD 00 21 E7",
        InstructionPacket.write(1, 116, b"\xff\xff\xfd\x00"),
    ),
}

UNSTUFFED_WRITE = "FF FF FD 00 01 09 00 03 74 00 FF FF FD 00 C9 07"
"""The same WRITE as dynamixel-sdk 4.1.0's Python txPacket sends it (not stuffed)."""


@pytest.mark.parametrize("name", GOLDEN)
def test_golden_encode(name: str) -> None:
    wire, packet = GOLDEN[name]
    assert encode_packet(packet) == bytes.fromhex(wire)


@pytest.mark.parametrize("name", GOLDEN)
def test_golden_decode(name: str) -> None:
    wire, packet = GOLDEN[name]
    assert decode_packet(bytes.fromhex(wire)) == packet


def test_unstuffed_write_as_the_sdk_sends_it() -> None:
    packet = InstructionPacket.write(1, 116, b"\xff\xff\xfd\x00")
    assert encode_instruction(packet, stuffing=False) == bytes.fromhex(UNSTUFFED_WRITE)
    assert decode_packet(bytes.fromhex(UNSTUFFED_WRITE)) == packet


def test_length_counts_params_plus_three() -> None:
    wire = encode_instruction(InstructionPacket(3, Instruction.WRITE, bytes(10)))
    assert wire[5] | (wire[6] << 8) == 10 + 3
    assert len(wire) == 7 + 10 + 3


def test_known_instructions_become_the_enum() -> None:
    assert InstructionPacket(1, 0x02, b"").instruction is Instruction.READ
    assert InstructionPacket(1, 0x7F, b"").instruction == 0x7F  # unknown stays an int


def test_instruction_codes() -> None:
    codes = {name: int(member) for name, member in Instruction.__members__.items()}
    assert codes == {
        "PING": 0x01,
        "READ": 0x02,
        "WRITE": 0x03,
        "REG_WRITE": 0x04,
        "ACTION": 0x05,
        "FACTORY_RESET": 0x06,
        "REBOOT": 0x08,
        "CLEAR": 0x10,
        "STATUS": 0x55,
        "SYNC_READ": 0x82,
        "SYNC_WRITE": 0x83,
        "FAST_SYNC_READ": 0x8A,
        "BULK_READ": 0x92,
        "BULK_WRITE": 0x93,
        "FAST_BULK_READ": 0x9A,
    }
    assert BROADCAST_ID == 0xFE


# -- the status error byte ------------------------------------------------------------------


def test_error_byte() -> None:
    assert [int(code) for code in ErrorCode] == [1, 2, 3, 4, 5, 6, 7]
    status = StatusPacket(1, 0x80 | ErrorCode.ACCESS)
    assert status.alert
    assert status.error_code == ErrorCode.ACCESS
    assert status.describe_error().startswith("access error (7); hardware alert")
    assert describe_error(0) == "no error"
    assert describe_error(0x80).startswith("hardware alert")
    assert describe_error(ErrorCode.CRC) == "CRC error (3)"
    assert describe_error(0x09) == "unknown error (9)"
    assert not StatusPacket(1, ErrorCode.DATA_RANGE).alert
    with pytest.raises(ValueError, match="error"):
        describe_error(256)


# -- builders: argument checks --------------------------------------------------------------


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: InstructionPacket.read(253, 0, 1), "id: must be a device ID"),
        (lambda: InstructionPacket.read(BROADCAST_ID, 0, 1), "id: must be a device ID"),
        (lambda: InstructionPacket.read(1, 70000, 1), "address: must be an integer"),
        (lambda: InstructionPacket.read(1, 0, 0), "length: must be an integer 1..65535"),
        (lambda: InstructionPacket.write(1, 116, b""), "data: must not be empty"),
        (lambda: InstructionPacket.write(1, 116, "abc"), "data: must be bytes"),
        (lambda: InstructionPacket.ping(255), "id: must be 0..252 or 254"),
        (lambda: InstructionPacket.ping(True), "id: must be 0..252 or 254"),
        (lambda: InstructionPacket.factory_reset(1, 3), "option"),
        (lambda: InstructionPacket.sync_write(116, 4, {1: b"\x00"}), r"data\[1\]: must be 4"),
        (lambda: InstructionPacket.sync_write(116, 4, {}), "data: must name"),
        (lambda: InstructionPacket.sync_write(116, 1, [(1, b"a"), (1, b"b")]), "twice"),
        (lambda: InstructionPacket.sync_write(116, 1, {254: b"a"}), r"data\[254\]"),
        (lambda: InstructionPacket.sync_read(132, 4, []), "ids: must name"),
        (lambda: InstructionPacket.sync_read(132, 4, [1, 1]), "twice"),
        (lambda: InstructionPacket.bulk_read([(1, 0, 1), (1, 2, 1)]), r"reads\[1\].id"),
        (lambda: InstructionPacket.bulk_write([(1, 0, b"")]), r"writes\[0\].data"),
        (lambda: InstructionPacket(1, 0x55, b""), "use StatusPacket"),
        (lambda: InstructionPacket(1, 256, b""), "instruction"),
        (lambda: StatusPacket(1, error=300), "error"),
        (lambda: InstructionPacket.write(1, 0, bytes(MAX_LENGTH)), "too long"),
    ],
)
def test_builders_refuse_bad_arguments(build, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        packet = build()
        encode_packet(packet)


def test_encoders_check_the_id() -> None:
    with pytest.raises(ValueError, match="id"):
        encode_instruction(InstructionPacket(253, Instruction.PING))
    with pytest.raises(ValueError, match="id"):
        encode_status(StatusPacket(255))
    with pytest.raises(TypeError):
        encode_packet(b"not a packet")  # type: ignore[arg-type]


def test_largest_packet() -> None:
    packet = InstructionPacket.write(1, 0, bytes(MAX_LENGTH - 5))
    assert len(encode_instruction(packet)) == MAX_LENGTH + 7


# -- parameters, device side ----------------------------------------------------------------


def test_parse_params_of_each_instruction() -> None:
    assert parse_params(InstructionPacket.ping(1)) is None
    assert parse_params(InstructionPacket.read(1, 132, 4)) == ReadParams(132, 4)
    assert parse_params(InstructionPacket.write(1, 116, u32(512))) == WriteParams(116, u32(512))
    assert parse_params(InstructionPacket.reg_write(1, 104, u32(200))) == WriteParams(104, u32(200))
    assert parse_params(InstructionPacket.sync_read(132, 4, [1, 2])) == SyncReadParams(
        132, 4, (1, 2)
    )
    assert parse_params(InstructionPacket.fast_sync_read(132, 4, [3])) == SyncReadParams(
        132, 4, (3,)
    )
    sync = parse_params(InstructionPacket.sync_write(116, 4, {2: u32(170), 1: u32(150)}))
    assert sync == SyncWriteParams(116, 4, {2: u32(170), 1: u32(150)})
    assert list(sync.data) == [2, 1]  # packet order is kept
    assert parse_params(InstructionPacket.bulk_read([(1, 144, 2), (2, 146, 1)])) == (
        BulkRead(1, 144, 2),
        BulkRead(2, 146, 1),
    )
    assert parse_params(InstructionPacket.bulk_write([(1, 32, b"\xa0\x00"), (2, 31, b"P")])) == (
        BulkWrite(1, 32, b"\xa0\x00"),
        BulkWrite(2, 31, b"P"),
    )
    assert parse_params(InstructionPacket.factory_reset(1, 0xFF)) == 0xFF
    assert parse_params(InstructionPacket.clear_multi_turn(1)) == b"\x01DXL\x22"
    assert parse_ping_reply(StatusPacket.ping_reply(1, 1060, 45).params) == PingReply(1060, 45)


@pytest.mark.parametrize(
    "packet",
    [
        InstructionPacket(1, Instruction.PING, b"\x00"),
        InstructionPacket(1, Instruction.READ, b"\x84\x00\x04"),
        InstructionPacket(1, Instruction.WRITE, b"\x74\x00"),
        InstructionPacket(1, Instruction.FACTORY_RESET, b""),
        InstructionPacket(BROADCAST_ID, Instruction.SYNC_READ, b"\x84\x00\x04\x00"),
        InstructionPacket(BROADCAST_ID, Instruction.SYNC_WRITE, b"\x74\x00\x04\x00\x01\x00"),
        InstructionPacket(BROADCAST_ID, Instruction.SYNC_WRITE, b"\x74\x00\x00\x00\x01"),
        InstructionPacket(BROADCAST_ID, Instruction.SYNC_WRITE, b"\x74\x00\x01\x00\x01a\x01b"),
        InstructionPacket(BROADCAST_ID, Instruction.BULK_READ, b"\x01\x90\x00\x02"),
        InstructionPacket(BROADCAST_ID, Instruction.BULK_READ, bytes.fromhex("01 90 00 02 00") * 2),
        InstructionPacket(BROADCAST_ID, Instruction.BULK_WRITE, b""),
        InstructionPacket(BROADCAST_ID, Instruction.BULK_WRITE, b"\x01\x20\x00\x02\x00\xa0"),
        InstructionPacket(BROADCAST_ID, Instruction.BULK_WRITE, b"\x01\x20\x00\x00\x00"),
        InstructionPacket(BROADCAST_ID, Instruction.BULK_WRITE, b"\x01\x20\x00"),
        InstructionPacket(1, 0x7F, b""),
    ],
)
def test_parse_params_refuses_malformed(packet: InstructionPacket) -> None:
    with pytest.raises(ParameterError):
        parse_params(packet)


# -- round trips ----------------------------------------------------------------------------

device_ids = st.integers(0, 252)
params = st.lists(st.sampled_from([0xFF, 0xFD, 0x00]) | st.integers(0, 255), max_size=200).map(
    bytes
)
instructions = st.integers(0, 255).filter(lambda code: code != Instruction.STATUS)
instruction_packets = st.builds(
    InstructionPacket, device_ids | st.just(BROADCAST_ID), instructions, params
)
status_packets = st.builds(StatusPacket, device_ids, st.integers(0, 255), params)


@given(instruction_packets | status_packets)
def test_encode_decode_round_trip(packet) -> None:
    assert decode_packet(encode_packet(packet)) == packet


@given(instruction_packets | status_packets)
def test_unstuffed_round_trip(packet) -> None:
    # Unstuffed bodies decode too, except the one ambiguous case: FF FF FD FD reads as stuffed.
    decoded = decode_packet(encode_packet(packet, stuffing=False))
    if b"\xff\xff\xfd\xfd" in encode_packet(packet, stuffing=False)[7:-2]:
        assert decoded != packet
    else:
        assert decoded == packet


@given(instruction_packets)
def test_stuffing_changes_only_packets_with_the_pattern(packet: InstructionPacket) -> None:
    stuffed = encode_instruction(packet)
    plain = encode_instruction(packet, stuffing=False)
    body = bytes([packet.instruction]) + packet.params
    assert (stuffed == plain) == (b"\xff\xff\xfd" not in body)
    assert len(stuffed) - len(plain) == body.count(b"\xff\xff\xfd")


@given(
    st.integers(0, 0xFFFF),
    st.dictionaries(device_ids, st.binary(min_size=3, max_size=3), min_size=1, max_size=20),
)
def test_sync_write_round_trip(address: int, data: dict[int, bytes]) -> None:
    packet = InstructionPacket.sync_write(address, 3, data)
    assert len(encode_instruction(packet, stuffing=False)) == 14 + 4 * len(data)
    assert parse_params(decode_packet(encode_instruction(packet))) == SyncWriteParams(
        address, 3, data
    )


@given(
    st.lists(
        st.tuples(device_ids, st.integers(0, 0xFFFF), st.binary(min_size=1, max_size=8)),
        min_size=1,
        max_size=10,
        unique_by=lambda entry: entry[0],
    )
)
def test_bulk_write_round_trip(writes: list[tuple[int, int, bytes]]) -> None:
    packet = decode_packet(encode_instruction(InstructionPacket.bulk_write(writes)))
    assert parse_params(packet) == tuple(BulkWrite(*entry) for entry in writes)


def test_decode_packet_refuses_anything_but_one_frame() -> None:
    ping = encode_instruction(InstructionPacket.ping(1))
    with pytest.raises(DecodeError):
        decode_packet(ping + ping)
    with pytest.raises(DecodeError) as excinfo:
        decode_packet(ping[:-1])
    assert excinfo.value.kind == DecodeError.TRUNCATED
    with pytest.raises(DecodeError) as excinfo:
        decode_packet(b"\x00" + ping)
    assert excinfo.value.kind == DecodeError.GARBAGE
