"""DYNAMIXEL Protocol 2.0 instruction and status packets.

Wire format (ROBOTIS e-Manual, Protocol 2.0, "Instruction Packet" and "Status Packet")::

    FF FF FD 00  ID  LEN_L LEN_H  INST  [ERR]  PARAM…  CRC_L CRC_H

- ``FF FF FD`` is the header and ``00`` the reserved byte;
- ``ID`` addresses one device, 0..252, or all of them with the broadcast ID 254 (0xFE); 253 and
  255 are never used, so that an ID cannot look like a header byte;
- ``LEN`` (little-endian) counts the bytes after it: instruction, error byte (status packets only),
  parameters and the two CRC bytes, i.e. parameters + 3 for an instruction packet, after byte
  stuffing;
- a status packet is the instruction 0x55 followed by the error byte;
- the CRC is described in :mod:`.crc`.

Parameters of each instruction (same page, "Instruction Details"); addresses and lengths are
16-bit little-endian:

=================  ============================================================================
PING               none; the status carries model number (16 bit) and firmware version (8 bit)
READ               address, length; the status carries the data
WRITE, REG_WRITE   address, data
ACTION, REBOOT     none
FACTORY_RESET      option: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate
CLEAR              0x01 then 44 58 4C 22: reset the multi-turn count of Present Position
SYNC_READ          address, length, then one ID per device (broadcast packet)
FAST_SYNC_READ     as SYNC_READ; the devices answer with one combined status packet
SYNC_WRITE         address, length, then per device its ID and ``length`` data bytes
BULK_READ          per device: ID, address, length
BULK_WRITE         per device: ID, address, length, data
=================  ============================================================================

The instruction codes match the e-Manual's table and dynamixel-sdk 4.1.0 (``robotis_def.py``),
which also defines FAST_BULK_READ 0x9A. Status error byte: bit 7 is the hardware alert (the
device has a hardware error; read Hardware Error Status, address 70), bits 0..6 the error number
of this instruction, 1..7 as in :class:`ErrorCode`.

Builders (``InstructionPacket.read(…)`` and friends) are what a host sends; the ``parse_…``
functions take parameters apart on the device side and raise :class:`ParameterError` when they
do not have the shape the instruction needs.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

from .crc import crc16, stuff

HEADER = b"\xff\xff\xfd\x00"
"""The three header bytes and the reserved byte that start every packet."""

BROADCAST_ID = 0xFE
"""Packet ID that addresses every device on the bus."""

MAX_DEVICE_ID = 252
"""Largest ID a device can have (IDs 0..252)."""

MAX_LENGTH = 1024
"""Largest LEN field this module produces or accepts by default.

dynamixel-sdk 4.1.0 uses 1024 both as its largest transmitted packet and as the largest LEN it
accepts in a reply (``TXPACKET_MAX_LEN``, ``RXPACKET_MAX_LEN``); real X-series traffic is far
smaller.
"""


class Instruction(enum.IntEnum):
    """Instruction codes of Protocol 2.0."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


PING = Instruction.PING
READ = Instruction.READ
WRITE = Instruction.WRITE
REG_WRITE = Instruction.REG_WRITE
ACTION = Instruction.ACTION
FACTORY_RESET = Instruction.FACTORY_RESET
REBOOT = Instruction.REBOOT
CLEAR = Instruction.CLEAR
STATUS = Instruction.STATUS
SYNC_READ = Instruction.SYNC_READ
SYNC_WRITE = Instruction.SYNC_WRITE
FAST_SYNC_READ = Instruction.FAST_SYNC_READ
BULK_READ = Instruction.BULK_READ
BULK_WRITE = Instruction.BULK_WRITE
FAST_BULK_READ = Instruction.FAST_BULK_READ

_KNOWN_INSTRUCTIONS = frozenset(Instruction)


class ErrorCode(enum.IntEnum):
    """Error numbers of a status packet's error byte (its low 7 bits)."""

    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


ERROR_ALERT = 0x80
"""Bit 7 of the error byte: the device has a hardware error (see Hardware Error Status)."""

ERROR_NAMES: Mapping[int, str] = {
    ErrorCode.RESULT_FAIL: "result fail",
    ErrorCode.INSTRUCTION: "instruction error",
    ErrorCode.CRC: "CRC error",
    ErrorCode.DATA_RANGE: "data range error",
    ErrorCode.DATA_LENGTH: "data length error",
    ErrorCode.DATA_LIMIT: "data limit error",
    ErrorCode.ACCESS: "access error",
}
"""Short names of the error numbers, after the e-Manual's table."""

ERROR_DESCRIPTIONS: Mapping[int, str] = {
    ErrorCode.RESULT_FAIL: "the device failed to process the instruction",
    ErrorCode.INSTRUCTION: "undefined instruction, or ACTION without a registered REG_WRITE",
    ErrorCode.CRC: "the instruction packet's CRC did not match",
    ErrorCode.DATA_RANGE: "the value is outside the address's minimum..maximum",
    ErrorCode.DATA_LENGTH: "the data is shorter than the item at the address",
    ErrorCode.DATA_LIMIT: "the value is outside a limit set in the control table",
    ErrorCode.ACCESS: ("read-only or undefined address, or EEPROM written while torque is enabled"),
}
"""What each error number means, in one line each."""


def describe_error(error: int) -> str:
    """A one-line description of a status error byte, e.g. ``"access error (7)"``.

    ``0`` is ``"no error"``; the hardware alert bit adds ``"hardware alert"``; an error number
    outside 1..7 is described as unknown.
    """
    if not 0 <= error <= 0xFF:
        raise ValueError(f"error: must be a byte 0..255, got {error!r}")
    parts = []
    code = error & 0x7F
    if code:
        name = ERROR_NAMES.get(code, "unknown error")
        parts.append(f"{name} ({code})")
    if error & ERROR_ALERT:
        parts.append("hardware alert (read Hardware Error Status, address 70)")
    return "; ".join(parts) if parts else "no error"


class ParameterError(ValueError):
    """An instruction's parameters do not have the shape that instruction needs."""


def _check_byte(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFF:
        raise ValueError(f"{name}: must be an integer 0..255, got {value!r}")
    return value


def _check_word(name: str, value: object, minimum: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not minimum <= value <= 0xFFFF:
        raise ValueError(f"{name}: must be an integer {minimum}..65535, got {value!r}")
    return value


def _check_device_id(name: str, value: object, *, broadcast: bool = False) -> int:
    ok = isinstance(value, int) and not isinstance(value, bool)
    ok = ok and (0 <= value <= MAX_DEVICE_ID or (broadcast and value == BROADCAST_ID))
    if not ok:
        allowed = "0..252 or 254 (broadcast)" if broadcast else "a device ID 0..252"
        raise ValueError(f"{name}: must be {allowed}, got {value!r}")
    return value  # type: ignore[return-value]


def _as_bytes(name: str, value: object) -> bytes:
    if isinstance(value, (bytes, bytearray, memoryview)):
        return bytes(value)
    if isinstance(value, str):
        raise ValueError(f"{name}: must be bytes, got a str")
    try:
        return bytes(value)  # type: ignore[call-overload]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: must be bytes or a sequence of integers 0..255") from exc


_U16 = struct.Struct("<H")


def _u16(value: int) -> bytes:
    return _U16.pack(value)


@dataclass(frozen=True)
class InstructionPacket:
    """A packet a host sends: device ``id``, ``instruction`` code and raw ``params``.

    Any byte values are accepted here, so that a decoder can represent whatever arrived (a device
    answers an unknown instruction with an instruction error); :func:`encode_instruction` checks
    the ID. ``params`` are the unstuffed parameter bytes.
    """

    id: int
    instruction: int
    params: bytes = field(default=b"")

    def __post_init__(self) -> None:
        _check_byte("id", self.id)
        _check_byte("instruction", self.instruction)
        if self.instruction == Instruction.STATUS:
            raise ValueError("instruction: 0x55 is the status instruction; use StatusPacket")
        if self.instruction in _KNOWN_INSTRUCTIONS:
            object.__setattr__(self, "instruction", Instruction(self.instruction))
        object.__setattr__(self, "params", _as_bytes("params", self.params))

    # Builders: the packets a host sends -------------------------------------------------

    @classmethod
    def ping(cls, id: int) -> InstructionPacket:
        """PING one device, or every device with ``BROADCAST_ID``."""
        return cls(_check_device_id("id", id, broadcast=True), PING)

    @classmethod
    def read(cls, id: int, address: int, length: int) -> InstructionPacket:
        """READ ``length`` bytes from ``address`` of one device (broadcast gets no answer)."""
        _check_device_id("id", id)
        params = _u16(_check_word("address", address)) + _u16(_check_word("length", length, 1))
        return cls(id, READ, params)

    @classmethod
    def write(cls, id: int, address: int, data: bytes) -> InstructionPacket:
        """WRITE ``data`` at ``address`` of one device or of all of them."""
        _check_device_id("id", id, broadcast=True)
        data = _nonempty_data("data", data)
        return cls(id, WRITE, _u16(_check_word("address", address)) + data)

    @classmethod
    def reg_write(cls, id: int, address: int, data: bytes) -> InstructionPacket:
        """REG_WRITE: like WRITE, but held until an ACTION."""
        _check_device_id("id", id, broadcast=True)
        data = _nonempty_data("data", data)
        return cls(id, REG_WRITE, _u16(_check_word("address", address)) + data)

    @classmethod
    def action(cls, id: int = BROADCAST_ID) -> InstructionPacket:
        """ACTION: run the registered REG_WRITE (every device by default)."""
        return cls(_check_device_id("id", id, broadcast=True), ACTION)

    @classmethod
    def reboot(cls, id: int) -> InstructionPacket:
        """REBOOT the device (the only way out of a hardware-error shutdown)."""
        return cls(_check_device_id("id", id, broadcast=True), REBOOT)

    @classmethod
    def factory_reset(cls, id: int, option: int) -> InstructionPacket:
        """FACTORY_RESET: ``option`` 0xFF all, 0x01 all but the ID, 0x02 all but ID and baud."""
        _check_device_id("id", id, broadcast=True)
        if option not in FACTORY_RESET_OPTIONS:
            raise ValueError(f"option: must be 0xFF, 0x01 or 0x02, got {option!r}")
        return cls(id, FACTORY_RESET, bytes([option]))

    @classmethod
    def clear_multi_turn(cls, id: int) -> InstructionPacket:
        """CLEAR the multi-turn revolution count (Present Position back within one turn)."""
        return cls(_check_device_id("id", id, broadcast=True), CLEAR, CLEAR_MULTI_TURN)

    @classmethod
    def sync_read(cls, address: int, length: int, ids: Iterable[int]) -> InstructionPacket:
        """SYNC_READ the same ``length`` bytes at ``address`` from each of ``ids``, in order."""
        return cls(BROADCAST_ID, SYNC_READ, _sync_read_params(address, length, ids))

    @classmethod
    def fast_sync_read(cls, address: int, length: int, ids: Iterable[int]) -> InstructionPacket:
        """FAST_SYNC_READ: SYNC_READ's parameters, answered in one combined status packet."""
        return cls(BROADCAST_ID, FAST_SYNC_READ, _sync_read_params(address, length, ids))

    @classmethod
    def sync_write(
        cls, address: int, length: int, data: Mapping[int, bytes] | Iterable[tuple[int, bytes]]
    ) -> InstructionPacket:
        """SYNC_WRITE ``length`` bytes at ``address`` of each device: ``{id: data}``, in order."""
        params = bytearray(_u16(_check_word("address", address)))
        params += _u16(_check_word("length", length, 1))
        items = data.items() if isinstance(data, Mapping) else data
        seen: set[int] = set()
        for id, chunk in items:
            _check_device_id(f"data[{id!r}]", id)
            if id in seen:
                raise ValueError(f"data: ID {id} given twice")
            seen.add(id)
            chunk = _as_bytes(f"data[{id}]", chunk)
            if len(chunk) != length:
                raise ValueError(f"data[{id}]: must be {length} bytes, got {len(chunk)}")
            params.append(id)
            params += chunk
        if not seen:
            raise ValueError("data: must name at least one device")
        return cls(BROADCAST_ID, SYNC_WRITE, bytes(params))

    @classmethod
    def bulk_read(cls, reads: Iterable[tuple[int, int, int]]) -> InstructionPacket:
        """BULK_READ ``(id, address, length)`` from each device, in order; each ID at most once."""
        params = bytearray()
        seen: set[int] = set()
        for index, (id, address, length) in enumerate(reads):
            _check_device_id(f"reads[{index}].id", id)
            if id in seen:
                raise ValueError(f"reads[{index}].id: ID {id} given twice")
            seen.add(id)
            params.append(id)
            params += _u16(_check_word(f"reads[{index}].address", address))
            params += _u16(_check_word(f"reads[{index}].length", length, 1))
        if not seen:
            raise ValueError("reads: must name at least one device")
        return cls(BROADCAST_ID, BULK_READ, bytes(params))

    @classmethod
    def bulk_write(cls, writes: Iterable[tuple[int, int, bytes]]) -> InstructionPacket:
        """BULK_WRITE ``(id, address, data)`` to each device, in order; each ID at most once."""
        params = bytearray()
        seen: set[int] = set()
        for index, (id, address, data) in enumerate(writes):
            _check_device_id(f"writes[{index}].id", id)
            if id in seen:
                raise ValueError(f"writes[{index}].id: ID {id} given twice")
            seen.add(id)
            data = _nonempty_data(f"writes[{index}].data", data)
            params.append(id)
            params += _u16(_check_word(f"writes[{index}].address", address))
            params += _u16(_check_word(f"writes[{index}].data length", len(data), 1))
            params += data
        if not seen:
            raise ValueError("writes: must name at least one device")
        return cls(BROADCAST_ID, BULK_WRITE, bytes(params))


@dataclass(frozen=True)
class StatusPacket:
    """A device's reply: its ``id``, the ``error`` byte and the ``params`` (e.g. data read)."""

    id: int
    error: int = 0
    params: bytes = field(default=b"")

    def __post_init__(self) -> None:
        _check_byte("id", self.id)
        _check_byte("error", self.error)
        object.__setattr__(self, "params", _as_bytes("params", self.params))

    @property
    def alert(self) -> bool:
        """Whether the hardware-alert bit (0x80) is set."""
        return bool(self.error & ERROR_ALERT)

    @property
    def error_code(self) -> int:
        """The error number (low 7 bits): 0 for none, else usually an :class:`ErrorCode`."""
        return self.error & 0x7F

    def describe_error(self) -> str:
        """The error byte in words; see :func:`describe_error`."""
        return describe_error(self.error)

    @classmethod
    def ping_reply(cls, id: int, model_number: int, firmware: int, error: int = 0) -> StatusPacket:
        """The status a device answers PING with."""
        _check_word("model_number", model_number)
        return cls(id, error, _u16(model_number) + bytes([_check_byte("firmware", firmware)]))


FACTORY_RESET_OPTIONS = (0xFF, 0x01, 0x02)
"""FACTORY_RESET options: reset all, all but the ID, all but the ID and the baud rate."""

CLEAR_MULTI_TURN = b"\x01\x44\x58\x4c\x22"
"""CLEAR parameters that reset the multi-turn count: option 0x01 and the fixed bytes "DXL\"."""


def _nonempty_data(name: str, data: object) -> bytes:
    data = _as_bytes(name, data)
    if not data:
        raise ValueError(f"{name}: must not be empty")
    return data


def _sync_read_params(address: int, length: int, ids: Iterable[int]) -> bytes:
    params = bytearray(_u16(_check_word("address", address)))
    params += _u16(_check_word("length", length, 1))
    ids = list(ids)
    if not ids:
        raise ValueError("ids: must name at least one device")
    for index, id in enumerate(ids):
        _check_device_id(f"ids[{index}]", id)
    if len(set(ids)) != len(ids):
        raise ValueError("ids: an ID is given twice")
    return bytes(params + bytes(ids))


# Encoding -----------------------------------------------------------------------------------


def _frame(id: int, body: bytes, *, stuffing: bool) -> bytes:
    if stuffing:
        body = stuff(body)
    length = len(body) + 2
    if length > MAX_LENGTH:
        raise ValueError(f"params: packet too long (LEN {length} > {MAX_LENGTH})")
    head = HEADER + bytes([id]) + _u16(length)
    crc = crc16(body, crc16(head))
    return head + body + _u16(crc)


def encode_instruction(packet: InstructionPacket, *, stuffing: bool = True) -> bytes:
    """The bytes of an instruction packet, with CRC.

    ``stuffing=False`` reproduces what the Python dynamixel-sdk 4.1.0 sends (it never stuffs);
    the two differ only when the parameters contain ``FF FF FD``.
    """
    _check_device_id("id", packet.id, broadcast=True)
    body = bytes([packet.instruction]) + packet.params
    return _frame(packet.id, body, stuffing=stuffing)


def encode_status(packet: StatusPacket, *, stuffing: bool = True) -> bytes:
    """The bytes of a status packet, with CRC.

    The ID is a device's (0..252) or 254: dynamixel-sdk accepts the broadcast ID in the combined
    reply to FAST_SYNC_READ / FAST_BULK_READ.
    """
    _check_device_id("id", packet.id, broadcast=True)
    body = bytes([Instruction.STATUS, packet.error]) + packet.params
    return _frame(packet.id, body, stuffing=stuffing)


def encode_packet(packet: InstructionPacket | StatusPacket, *, stuffing: bool = True) -> bytes:
    """The bytes of either kind of packet."""
    if isinstance(packet, StatusPacket):
        return encode_status(packet, stuffing=stuffing)
    if isinstance(packet, InstructionPacket):
        return encode_instruction(packet, stuffing=stuffing)
    raise TypeError(f"packet: expected InstructionPacket or StatusPacket, got {packet!r}")


# Parameters, device side --------------------------------------------------------------------


class ReadParams(NamedTuple):
    """READ (and SYNC_READ without IDs): where and how much."""

    address: int
    length: int


class WriteParams(NamedTuple):
    """WRITE or REG_WRITE: where, and the bytes."""

    address: int
    data: bytes


class SyncReadParams(NamedTuple):
    """SYNC_READ or FAST_SYNC_READ: where, how much, and from which devices in order."""

    address: int
    length: int
    ids: tuple[int, ...]


class SyncWriteParams(NamedTuple):
    """SYNC_WRITE: where, how much, and each device's bytes (in packet order)."""

    address: int
    length: int
    data: dict[int, bytes]


class BulkRead(NamedTuple):
    """One device's part of a BULK_READ."""

    id: int
    address: int
    length: int


class BulkWrite(NamedTuple):
    """One device's part of a BULK_WRITE."""

    id: int
    address: int
    data: bytes


class PingReply(NamedTuple):
    """What a device answers PING with."""

    model_number: int
    firmware: int


def _exact(name: str, params: bytes, size: int) -> None:
    if len(params) != size:
        raise ParameterError(f"{name}: expected {size} parameter bytes, got {len(params)}")


def parse_read(params: bytes) -> ReadParams:
    """Address and length of a READ."""
    _exact("READ", params, 4)
    address, length = struct.unpack("<HH", params)
    return ReadParams(address, length)


def parse_write(params: bytes) -> WriteParams:
    """Address and data of a WRITE or REG_WRITE (at least one data byte)."""
    if len(params) < 3:
        raise ParameterError(f"WRITE: expected an address and data, got {len(params)} bytes")
    return WriteParams(_U16.unpack_from(params)[0], bytes(params[2:]))


def parse_factory_reset(params: bytes) -> int:
    """The option byte of a FACTORY_RESET (its value is not checked here)."""
    _exact("FACTORY_RESET", params, 1)
    return params[0]


def parse_sync_read(params: bytes) -> SyncReadParams:
    """Address, length and device IDs of a SYNC_READ or FAST_SYNC_READ."""
    if len(params) < 5:
        raise ParameterError(f"SYNC_READ: expected address, length, IDs; got {len(params)} bytes")
    address, length = struct.unpack_from("<HH", params)
    return SyncReadParams(address, length, tuple(params[4:]))


def parse_sync_write(params: bytes) -> SyncWriteParams:
    """Address, length and per-device data of a SYNC_WRITE."""
    if len(params) < 4:
        raise ParameterError(f"SYNC_WRITE: expected address and length, got {len(params)} bytes")
    address, length = struct.unpack_from("<HH", params)
    rest = params[4:]
    if length == 0 or not rest or len(rest) % (length + 1):
        raise ParameterError(
            f"SYNC_WRITE: {len(rest)} bytes after the header are not whole (ID + {length} bytes)"
        )
    data: dict[int, bytes] = {}
    for start in range(0, len(rest), length + 1):
        id = rest[start]
        if id in data:
            raise ParameterError(f"SYNC_WRITE: ID {id} given twice")
        data[id] = bytes(rest[start + 1 : start + 1 + length])
    return SyncWriteParams(address, length, data)


def parse_bulk_read(params: bytes) -> tuple[BulkRead, ...]:
    """The ``(id, address, length)`` of each device of a BULK_READ."""
    if not params or len(params) % 5:
        raise ParameterError(f"BULK_READ: {len(params)} bytes are not whole 5-byte entries")
    entries = tuple(
        BulkRead(*struct.unpack_from("<BHH", params, i)) for i in range(0, len(params), 5)
    )
    _unique("BULK_READ", [entry.id for entry in entries])
    return entries


def parse_bulk_write(params: bytes) -> tuple[BulkWrite, ...]:
    """The ``(id, address, data)`` of each device of a BULK_WRITE."""
    entries = []
    offset = 0
    while offset < len(params):
        if len(params) - offset < 5:
            raise ParameterError(f"BULK_WRITE: truncated entry at parameter {offset}")
        id, address, length = struct.unpack_from("<BHH", params, offset)
        offset += 5
        if length == 0 or len(params) - offset < length:
            raise ParameterError(f"BULK_WRITE: entry for ID {id} has a bad length {length}")
        entries.append(BulkWrite(id, address, bytes(params[offset : offset + length])))
        offset += length
    if not entries:
        raise ParameterError("BULK_WRITE: no entries")
    _unique("BULK_WRITE", [entry.id for entry in entries])
    return tuple(entries)


def parse_ping_reply(params: bytes) -> PingReply:
    """Model number and firmware version from a PING status."""
    _exact("PING status", params, 3)
    model, firmware = struct.unpack("<HB", params)
    return PingReply(model, firmware)


def _unique(name: str, ids: list[int]) -> None:
    if len(set(ids)) != len(ids):
        raise ParameterError(f"{name}: an ID is given twice")


_NO_PARAMS = frozenset({PING, ACTION, REBOOT})


Params = (
    ReadParams
    | WriteParams
    | SyncReadParams
    | SyncWriteParams
    | tuple[BulkRead, ...]
    | tuple[BulkWrite, ...]
    | int
    | bytes
    | None
)
"""What :func:`parse_params` returns, depending on the instruction."""


def parse_params(packet: InstructionPacket) -> Params:
    """The parameters of ``packet`` taken apart according to its instruction.

    PING, ACTION and REBOOT give ``None`` (and must have no parameters); READ a
    :class:`ReadParams`; WRITE and REG_WRITE a :class:`WriteParams`; SYNC_READ and
    FAST_SYNC_READ a :class:`SyncReadParams`; SYNC_WRITE a :class:`SyncWriteParams`; BULK_READ
    and FAST_BULK_READ a tuple of :class:`BulkRead`; BULK_WRITE a tuple of :class:`BulkWrite`;
    FACTORY_RESET its option byte; CLEAR its raw parameter bytes. An unknown instruction raises
    :class:`ParameterError` (a device answers it with an instruction error).
    """
    instruction, params = packet.instruction, packet.params
    if instruction in _NO_PARAMS:
        if params:
            raise ParameterError(
                f"{Instruction(instruction).name}: expected no parameters, got {len(params)}"
            )
        return None
    parsers = {
        READ: parse_read,
        WRITE: parse_write,
        REG_WRITE: parse_write,
        FACTORY_RESET: parse_factory_reset,
        SYNC_READ: parse_sync_read,
        FAST_SYNC_READ: parse_sync_read,
        SYNC_WRITE: parse_sync_write,
        BULK_READ: parse_bulk_read,
        FAST_BULK_READ: parse_bulk_read,
        BULK_WRITE: parse_bulk_write,
        CLEAR: bytes,
    }
    parser = parsers.get(instruction)
    if parser is None:
        raise ParameterError(f"unknown instruction 0x{instruction:02X}")
    return parser(params)
