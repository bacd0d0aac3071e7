"""The incremental Protocol 2.0 decoder: chunking, resynchronisation, bad CRCs, stuffing.

Frames are the e-Manual's examples (literals, as in the packet tests) and packets encoded by this
package, whose encoder those examples pin.
"""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocols.dynamixel import (
    BROADCAST_ID,
    DecodeError,
    Instruction,
    InstructionPacket,
    PacketDecoder,
    StatusPacket,
    encode_packet,
)

PING = bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")
PING_STATUS = bytes.fromhex("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")
READ = bytes.fromhex("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")
READ_STATUS = bytes.fromhex("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0")
SYNC_WRITE = bytes.fromhex(
    "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87"
)
STUFFED_WRITE = bytes.fromhex("FF FF FD 00 01 0A 00 03 74 00 FF FF FD FD 00 21 E7")
UNSTUFFED_WRITE = bytes.fromhex("FF FF FD 00 01 09 00 03 74 00 FF FF FD 00 C9 07")

PACKETS = {
    PING: InstructionPacket(1, Instruction.PING),
    PING_STATUS: StatusPacket(1, 0, b"\x06\x04\x26"),
    READ: InstructionPacket(1, Instruction.READ, b"\x84\x00\x04\x00"),
    READ_STATUS: StatusPacket(1, 0, b"\xa6\x00\x00\x00"),
    SYNC_WRITE: InstructionPacket(
        BROADCAST_ID,
        Instruction.SYNC_WRITE,
        bytes.fromhex("74 00 04 00 01 96 00 00 00 02 AA 00 00 00"),
    ),
    STUFFED_WRITE: InstructionPacket(1, Instruction.WRITE, b"\x74\x00\xff\xff\xfd\x00"),
    UNSTUFFED_WRITE: InstructionPacket(1, Instruction.WRITE, b"\x74\x00\xff\xff\xfd\x00"),
}
STREAM = b"".join(PACKETS)
EXPECTED = list(PACKETS.values())


def corrupt(frame: bytes) -> bytes:
    """The frame with its last CRC byte changed."""
    return frame[:-1] + bytes([frame[-1] ^ 0x5A])


def decode_whole(data: bytes, **options) -> list:
    decoder = PacketDecoder(**options)
    return decoder.feed(data) + decoder.flush()


def decode_in_chunks(data: bytes, sizes: list[int], **options) -> list:
    decoder = PacketDecoder(**options)
    out, start = [], 0
    for size in sizes:
        out += decoder.feed(data[start : start + size])
        start += size
    out += decoder.feed(data[start:])
    return out + decoder.flush()


@pytest.mark.parametrize("frame", PACKETS)
def test_each_frame_whole(frame: bytes) -> None:
    decoder = PacketDecoder()
    assert decoder.feed(frame) == [PACKETS[frame]]
    assert decoder.pending == 0
    assert decoder.flush() == []


def test_stream_whole() -> None:
    assert PacketDecoder().feed(STREAM) == EXPECTED


@pytest.mark.parametrize("split", range(len(STREAM) + 1))
def test_stream_in_two_halves_at_every_point(split: int) -> None:
    decoder = PacketDecoder()
    assert decoder.feed(STREAM[:split]) + decoder.feed(STREAM[split:]) == EXPECTED


def test_stream_byte_by_byte() -> None:
    decoder = PacketDecoder()
    out = []
    for byte in STREAM:
        out += decoder.feed(bytes([byte]))
    assert out == EXPECTED
    assert decoder.bytes_decoded == len(STREAM)
    assert decoder.bytes_discarded == 0


def test_partial_frame_waits() -> None:
    decoder = PacketDecoder()
    assert decoder.feed(READ_STATUS[:10]) == []
    assert decoder.pending == 10
    assert decoder.feed(READ_STATUS[10:]) == [PACKETS[READ_STATUS]]


def test_stuffed_and_unstuffed_decode_alike() -> None:
    assert PacketDecoder().feed(STUFFED_WRITE) == PacketDecoder().feed(UNSTUFFED_WRITE)


def test_garbage_before_a_frame() -> None:
    garbage = b"\x00\x12\xff\xff\xfd\x01\xfe\xff"
    assert PacketDecoder().feed(garbage + PING) == [
        DecodeError(DecodeError.GARBAGE, garbage),
        PACKETS[PING],
    ]


def test_garbage_is_reported_when_its_end_is_known() -> None:
    decoder = PacketDecoder()
    assert decoder.feed(b"\x01\x02\x03\xff\xff") == []  # may still become a header
    assert decoder.feed(b"\xfd\x01") == []  # not a header: still garbage, end unknown
    assert decoder.feed(PING) == [
        DecodeError(DecodeError.GARBAGE, b"\x01\x02\x03\xff\xff\xfd\x01"),
        PACKETS[PING],
    ]


def test_garbage_without_end_is_reported_in_pieces() -> None:
    noise = bytes(range(200)) * 3  # holds no header
    out = PacketDecoder(max_error_bytes=100).feed(noise)
    assert [error.data for error in out] == [noise[i : i + 100] for i in range(0, 500, 100)]
    assert decode_whole(noise, max_error_bytes=100)[-1] == DecodeError("garbage", noise[500:])


def test_bad_crc_before_a_good_frame() -> None:
    out = PacketDecoder().feed(corrupt(READ) + READ_STATUS)
    assert out == [DecodeError(DecodeError.BAD_CRC, corrupt(READ)), PACKETS[READ_STATUS]]
    assert "CRC" in str(out[0])


def test_bad_crc_is_reported_at_once() -> None:
    decoder = PacketDecoder()
    assert decoder.feed(corrupt(READ_STATUS)) == [
        DecodeError(DecodeError.BAD_CRC, corrupt(READ_STATUS))
    ]
    assert decoder.pending == 0


def test_frame_cut_short_does_not_swallow_the_next() -> None:
    # A sender restarted mid-frame: the cut frame's LEN reaches into the next frame, whose header
    # lies inside the bad frame; decoding resumes there.
    cut = SYNC_WRITE[:12]
    out = PacketDecoder().feed(cut + PING + READ + READ_STATUS)
    assert out == [
        DecodeError(DecodeError.BAD_CRC, cut),
        PACKETS[PING],
        PACKETS[READ],
        PACKETS[READ_STATUS],
    ]


@pytest.mark.parametrize("tail", range(1, 4))
def test_bad_frame_ending_inside_the_next_header(tail: int) -> None:
    # A frame cut after 3 bytes of body whose LEN ends ``tail`` bytes into the next frame's
    # header: the report stops before that header and the next frame is decoded.
    cut = bytes.fromhex("FF FF FD 00 01") + (3 + tail).to_bytes(2, "little") + b"\x03\x74\x00"
    out = PacketDecoder().feed(cut + PING + READ)
    assert out == [DecodeError(DecodeError.BAD_CRC, cut), PACKETS[PING], PACKETS[READ]]


@pytest.mark.parametrize(
    ("header", "kind"),
    [
        ("FF FF FD 00 01 FF FF", DecodeError.BAD_LENGTH),  # LEN 65535
        ("FF FF FD 00 01 01 04", DecodeError.BAD_LENGTH),  # LEN 1025
        ("FF FF FD 00 01 02 00", DecodeError.BAD_LENGTH),  # LEN 2: no room for the CRC
        ("FF FF FD 00 FD 03 00", DecodeError.BAD_ID),
        ("FF FF FD 00 FF 03 00", DecodeError.BAD_ID),
    ],
)
def test_implausible_header_resynchronises(header: str, kind: str) -> None:
    bad = bytes.fromhex(header) + b"\x01\x02"
    out = PacketDecoder().feed(bad + PING)
    assert out == [DecodeError(kind, bad), PACKETS[PING]]


def test_max_length_is_configurable() -> None:
    assert PacketDecoder(max_length=8).feed(READ_STATUS + PING) == [
        PACKETS[READ_STATUS],
        PACKETS[PING],
    ]
    long_status = encode_packet(StatusPacket(1, 0, bytes(20)))
    out = PacketDecoder(max_length=8).feed(long_status + PING)
    assert [item.kind for item in out[:-1]] == [DecodeError.BAD_LENGTH]
    assert out[-1] == PACKETS[PING]


def test_header_inside_an_unstuffed_payload_does_not_break_framing() -> None:
    # An unstuffed body holding a whole header: read by LEN, it is just data.
    packet = InstructionPacket(1, Instruction.WRITE, b"\x74\x00\xff\xff\xfd\x00\x01\x03\x00")
    frame = encode_packet(packet, stuffing=False)
    assert PacketDecoder().feed(frame + PING) == [packet, PACKETS[PING]]


def test_status_without_error_byte_is_malformed() -> None:
    from firmware_protocols.dynamixel import crc16

    head = bytes.fromhex("FF FF FD 00 01 03 00 55")
    frame = head + crc16(head).to_bytes(2, "little")
    assert PacketDecoder().feed(frame + PING) == [
        DecodeError(DecodeError.MALFORMED, frame),
        PACKETS[PING],
    ]


def test_flush_reports_a_truncated_frame_and_keeps_later_ones() -> None:
    decoder = PacketDecoder()
    assert decoder.feed(SYNC_WRITE[:9]) == []
    assert decoder.flush() == [DecodeError(DecodeError.TRUNCATED, SYNC_WRITE[:9])]
    assert decoder.pending == 0
    # A cut frame followed by a complete one shorter than the cut frame's LEN.
    decoder = PacketDecoder()
    assert decoder.feed(SYNC_WRITE[:9] + PING) == []
    assert decoder.flush() == [DecodeError(DecodeError.TRUNCATED, SYNC_WRITE[:9]), PACKETS[PING]]


def test_reset_forgets_buffered_bytes() -> None:
    decoder = PacketDecoder()
    decoder.feed(READ[:5])
    decoder.reset()
    assert decoder.pending == 0
    assert decoder.feed(PING) == [PACKETS[PING]]


def test_decode_error_is_a_value() -> None:
    error = DecodeError(DecodeError.BAD_CRC, b"\xff\xff", "detail")
    assert isinstance(error, ValueError)
    assert error == DecodeError("bad_crc", b"\xff\xff")
    assert error != DecodeError("garbage", b"\xff\xff")
    assert len({error, DecodeError("bad_crc", b"\xff\xff")}) == 1
    assert "bad_crc (detail): discarded 2 bytes: ff ff" in str(error)
    copy = pickle.loads(pickle.dumps(error))
    assert copy == error and str(copy) == str(error)


@pytest.mark.parametrize(
    "options", [{"max_length": 3}, {"max_error_bytes": 0}, {"max_length": True}]
)
def test_options_are_checked(options) -> None:
    with pytest.raises(ValueError):
        PacketDecoder(**options)


# -- properties -----------------------------------------------------------------------------

frames = st.sampled_from(list(PACKETS)) | st.sampled_from(list(PACKETS)).map(corrupt)
NOISE_PIECES = [
    b"\xff",
    b"\xfd",
    b"\x00",
    b"\x01",
    b"\x03\x00",
    b"\xff\xff",
    b"\xff\xff\xfd\x00",
    bytes.fromhex("FF FF FD 00 01 03 00"),  # a header whose frame ends inside the next header
    bytes.fromhex("FF FF FD 00 01 05 00 55"),
]
"""Noise made of header fragments, so that random streams meet every resynchronisation case."""

noise = st.binary(max_size=12) | st.lists(st.sampled_from(NOISE_PIECES), max_size=6).map(b"".join)
streams = st.lists(frames | noise, max_size=12).map(b"".join)


def as_values(items: list) -> list:
    return [(item.kind, item.data) if isinstance(item, DecodeError) else item for item in items]


@settings(max_examples=300)
@given(st.binary(max_size=400), st.lists(st.integers(0, 40), max_size=30))
def test_any_bytes_never_raise(data: bytes, sizes: list[int]) -> None:
    decoder = PacketDecoder(max_error_bytes=64)
    out, start = [], 0
    for size in sizes:
        out += decoder.feed(data[start : start + size])
        start += size
    out += decoder.feed(data[start:]) + decoder.flush()
    assert all(isinstance(item, InstructionPacket | StatusPacket | DecodeError) for item in out)
    assert decoder.bytes_decoded + decoder.bytes_discarded == len(data)
    assert decoder.pending == 0


@settings(max_examples=300)
@given(streams, st.lists(st.integers(0, 30), max_size=40))
def test_chunking_does_not_change_the_result(data: bytes, sizes: list[int]) -> None:
    whole = decode_whole(data, max_error_bytes=16)
    assert as_values(decode_in_chunks(data, sizes, max_error_bytes=16)) == as_values(whole)
    assert as_values(decode_in_chunks(data, [1] * len(data), max_error_bytes=16)) == as_values(
        whole
    )


@given(streams)
def test_every_byte_is_accounted_for_once(data: bytes) -> None:
    decoder = PacketDecoder()
    out = decoder.feed(data) + decoder.flush()
    discarded = b"".join(item.data for item in out if isinstance(item, DecodeError))
    assert decoder.bytes_discarded == len(discarded)
    assert decoder.bytes_decoded + decoder.bytes_discarded == len(data)


@given(noise, st.lists(st.sampled_from(list(PACKETS)), max_size=10))
def test_noise_never_costs_the_good_frames_after_it(junk: bytes, good: list[bytes]) -> None:
    # Even a partial header at the end of the noise, whose LEN reaches into the real frames, only
    # delays them: its CRC fails (or it is cut off at flush) and decoding resumes inside it.
    out = decode_whole(junk + b"".join(good))
    packets = [item for item in out if not isinstance(item, DecodeError)]
    assert packets == [PACKETS[frame] for frame in good]
