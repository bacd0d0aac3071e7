"""CRC-16 and byte stuffing of DYNAMIXEL Protocol 2.0.

Oracles: the CRC catalogue's check value of CRC-16/UMTS (= BUYPASS, the same parameters), the
CRCs of the e-Manual's example packets, and dynamixel-sdk 4.1.0's own ``updateCRC`` and
``addStuffing``.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import Protocol2PacketHandler
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.dynamixel import crc16, stuff, unstuff
from firmware_protocols.dynamixel.crc import CRC_TABLE

SDK = Protocol2PacketHandler()

# e-Manual Protocol 2.0 examples (checked against dynamixel-sdk 4.1.0): frame without its CRC,
# and the CRC as sent (low byte first).
EXAMPLES = [
    ("FF FF FD 00 01 03 00 01", "19 4E"),  # PING ID 1
    ("FF FF FD 00 01 07 00 55 00 06 04 26", "65 5D"),  # its status
    ("FF FF FD 00 01 07 00 02 84 00 04 00", "1D 15"),  # READ 132, 4
    ("FF FF FD 00 01 08 00 55 00 A6 00 00 00", "8C C0"),  # its status
    ("FF FF FD 00 01 09 00 03 74 00 00 02 00 00", "CA 89"),  # WRITE 116 = 512
    ("FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00", "82 87"),
    ("FF FF FD 00 01 0A 00 03 74 00 FF FF FD FD 00", "21 E7"),  # stuffed WRITE
]

# Bytes rich in the stuffing pattern, so that random bodies hit every case.
pattern_bytes = st.lists(
    st.sampled_from([0xFF, 0xFD, 0x00, 0x55]) | st.integers(0, 255), max_size=300
).map(bytes)


def test_check_value_of_the_catalogue() -> None:
    assert crc16(b"123456789") == 0xFEE8
    assert crc16(b"") == 0


@pytest.mark.parametrize(("frame", "crc"), EXAMPLES)
def test_crc_of_emanual_examples(frame: str, crc: str) -> None:
    assert crc16(bytes.fromhex(frame)).to_bytes(2, "little") == bytes.fromhex(crc)


def test_table_is_the_sdk_table() -> None:
    # The SDK carries the e-Manual's printed table; ours is generated from the polynomial.
    table = [SDK.updateCRC(0, [0, byte], 2) for byte in range(256)]
    assert table == list(CRC_TABLE)


@given(st.binary(max_size=300))
def test_crc_matches_sdk(data: bytes) -> None:
    assert crc16(data) == SDK.updateCRC(0, list(data), len(data))


@given(st.binary(max_size=100), st.binary(max_size=100))
def test_crc_is_incremental(a: bytes, b: bytes) -> None:
    assert crc16(b, crc16(a)) == crc16(a + b)


@pytest.mark.parametrize(
    ("body", "stuffed"),
    [
        ("", ""),
        ("03 74 00 00 02 00 00", "03 74 00 00 02 00 00"),
        ("03 74 00 FF FF FD 00", "03 74 00 FF FF FD FD 00"),
        ("FF FF FD", "FF FF FD FD"),
        ("FF FF FD FD", "FF FF FD FD FD"),
        ("FF FF FF FD", "FF FF FF FD FD"),
        ("FF FF FD FF FF FD", "FF FF FD FD FF FF FD FD"),
        ("FF FD FF FF", "FF FD FF FF"),
    ],
)
def test_stuffing_examples(body: str, stuffed: str) -> None:
    assert stuff(bytes.fromhex(body)) == bytes.fromhex(stuffed)
    assert unstuff(bytes.fromhex(stuffed)) == bytes.fromhex(body)


def test_unstuff_keeps_an_unstuffed_pattern() -> None:
    # dynamixel-sdk's Python txPacket sends FF FF FD unstuffed; it must come through unchanged.
    assert unstuff(bytes.fromhex("74 00 FF FF FD 00")) == bytes.fromhex("74 00 FF FF FD 00")
    assert unstuff(bytes.fromhex("FF FF FD")) == bytes.fromhex("FF FF FD")


@given(pattern_bytes)
def test_stuffing_round_trip(body: bytes) -> None:
    stuffed = stuff(body)
    assert unstuff(stuffed) == body
    assert len(stuffed) == len(body) + body.count(b"\xff\xff\xfd")
    # Every header pattern left in the stuffed body is followed by the stuffing byte.
    start = stuffed.find(b"\xff\xff\xfd")
    while start >= 0:
        assert stuffed[start + 3 : start + 4] == b"\xfd"
        start = stuffed.find(b"\xff\xff\xfd", start + 4)


@given(pattern_bytes.filter(lambda body: len(body) >= 1))
def test_stuffing_matches_sdk(body: bytes) -> None:
    # addStuffing takes a whole packet (header, LEN, body, room for the CRC) and returns the
    # stuffed packet; it stuffs the instruction and parameters only.
    length = len(body) + 2
    packet = [0xFF, 0xFF, 0xFD, 0x00, 0x01, length & 0xFF, length >> 8, *body, 0, 0]
    stuffed = SDK.addStuffing(packet)
    new_length = stuffed[5] | (stuffed[6] << 8)
    assert bytes(stuffed[7 : 7 + new_length - 2]) == stuff(body)
