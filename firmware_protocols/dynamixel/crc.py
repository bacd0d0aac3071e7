"""CRC-16 and byte stuffing of DYNAMIXEL Protocol 2.0 packets.

The checksum is the CRC-16 of the ROBOTIS e-Manual ("CRC Calculation", linked from the Protocol
2.0 page): polynomial 0x8005 (x¹⁶ + x¹⁵ + x² + 1), initial value 0, most significant bit first (no
reflection of input or output), no final XOR; in CRC catalogues this is CRC-16/UMTS, also called
CRC-16/BUYPASS, whose check value for ``b"123456789"`` is 0xFEE8. It covers the whole packet from
the first header byte to the last parameter, as transmitted (after byte stuffing), and is sent low
byte first. The lookup table is generated here from the polynomial; the tests compare it with the
table printed in the e-Manual and copied into dynamixel-sdk.

Byte stuffing keeps the header pattern ``FF FF FD`` out of a packet's body. The e-Manual's
"Packet Process" section: when sending, every ``FF FF FD`` inside the instruction and parameter
fields (never the header, never the CRC) gets an extra ``FD`` (``FF FF FD FD``); the length field
counts the stuffed bytes and the CRC is computed over them. A receiver computes the CRC over the
bytes as received, then removes the extra ``FD``.
"""

from __future__ import annotations

CRC_POLYNOMIAL = 0x8005
"""Generator polynomial of the Protocol 2.0 CRC-16 (x¹⁶ + x¹⁵ + x² + 1), bit 16 implied."""

STUFFING_PATTERN = b"\xff\xff\xfd"
"""Three bytes that, inside a packet's body, are followed by an extra ``FD`` when stuffed."""

_STUFF_BYTE = 0xFD


def _make_table(polynomial: int) -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ polynomial) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


CRC_TABLE: tuple[int, ...] = _make_table(CRC_POLYNOMIAL)
"""The 256-entry lookup table: the CRC register's update for each value of its top byte."""


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 of ``data`` as DYNAMIXEL Protocol 2.0 computes it.

    ``crc`` is the running value of an earlier call, so ``crc16(b, crc16(a)) == crc16(a + b)``;
    the default 0 is the protocol's initial value. The result is in 0..0xFFFF and is sent low
    byte first.
    """
    table = CRC_TABLE
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
    return crc


def stuff(body: bytes | bytearray | memoryview) -> bytes:
    """``body`` (instruction byte and parameters) with an ``FD`` added after every ``FF FF FD``.

    The pattern is matched on the original bytes, so ``FF FF FD FD`` becomes
    ``FF FF FD FD FD`` and ``unstuff`` restores it exactly.
    """
    body = bytes(body)
    if STUFFING_PATTERN not in body:
        return body
    out = bytearray()
    start = 0
    while True:
        hit = body.find(STUFFING_PATTERN, start)
        if hit < 0:
            out += body[start:]
            return bytes(out)
        end = hit + len(STUFFING_PATTERN)
        out += body[start:end]
        out.append(_STUFF_BYTE)
        start = end


def unstuff(body: bytes | bytearray | memoryview) -> bytes:
    """Remove the ``FD`` that stuffing added after each ``FF FF FD`` of ``body``.

    An ``FF FF FD`` not followed by ``FD`` is kept as it is: the Python dynamixel-sdk 4.1.0 sends
    packets unstuffed, and a receiver should accept those too. The one ambiguity is an unstuffed
    body that really contains ``FF FF FD FD``; it is read as stuffed, as the protocol says.
    """
    body = bytes(body)
    if STUFFING_PATTERN not in body:
        return body
    out = bytearray()
    start = 0
    while True:
        hit = body.find(STUFFING_PATTERN, start)
        if hit < 0:
            out += body[start:]
            return bytes(out)
        end = hit + len(STUFFING_PATTERN)
        out += body[start:end]
        start = end + 1 if end < len(body) and body[end] == _STUFF_BYTE else end
