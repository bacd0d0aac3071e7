"""Incremental decoder of DYNAMIXEL Protocol 2.0 byte streams.

:class:`PacketDecoder` takes bytes as they arrive, in chunks of any size, and returns the packets
they complete: :class:`~.packets.InstructionPacket` (what a device receives) and
:class:`~.packets.StatusPacket` (instruction 0x55, what a host receives), plus a
:class:`DecodeError` for every run of bytes it had to throw away. It never raises on its input.

Framing follows the e-Manual's "Processing Order of Reception": find the header ``FF FF FD 00``,
read ID and LEN, wait for LEN more bytes, check the CRC over the bytes as received, then remove
byte stuffing. Beyond that:

- **Both stuffed and unstuffed bodies are accepted.** The CRC covers the bytes as sent, so
  either form checks; an ``FF FF FD`` followed by ``FD`` is unstuffed, any other ``FF FF FD`` is
  kept (the Python dynamixel-sdk 4.1.0 does not stuff what it sends).
- **Resynchronisation.** Bytes before a header are reported as ``garbage``. A header whose ID is
  253 or 255 (``bad_id``) or whose LEN is below 3 or above ``max_length`` (``bad_length``) is not
  a packet: the decoder reports it with the bytes up to the next header and searches on from the
  byte after the header pattern, so a real packet that starts inside it is still found.
- **Bad CRC.** A frame whose CRC does not match is reported (``bad_crc``) at once, so a host can
  tell a corrupt reply from a missing one. Decoding resumes at the first header that starts
  inside the bad frame (a frame cut short by a restarted sender swallows the start of the next
  one, possibly only its first header bytes) or else right after it.
- **Status packets** need their error byte: a correct-CRC status frame without one is reported as
  ``malformed``.
- ``flush()`` says that no more bytes are coming (e.g. a reply timed out): an incomplete frame is
  reported as ``truncated`` and any complete packet buffered after its header is still decoded.

Every byte fed ends up in exactly one packet or one error (``bytes_decoded`` and
``bytes_discarded`` count them), and the sequence of results depends only on the bytes, not on
how they were split into chunks: errors are reported when the next header makes their extent
known, in pieces of at most ``max_error_bytes``.
"""

from __future__ import annotations

from .crc import crc16, unstuff
from .packets import HEADER, MAX_LENGTH, Instruction, InstructionPacket, StatusPacket

__all__ = ["DecodeError", "PacketDecoder", "decode_packet"]

_HEADER_SIZE = 7  # FF FF FD 00 ID LEN_L LEN_H
_MIN_LENGTH = 3  # instruction + CRC
_INVALID_IDS = (0xFD, 0xFF)  # never used, so that an ID cannot look like a header byte


class DecodeError(ValueError):
    """Bytes the decoder discarded, and why.

    Returned in :meth:`PacketDecoder.feed`'s list (not raised), so that a stream goes on being
    decoded; a caller may raise it. ``kind`` is one of ``GARBAGE``, ``BAD_ID``, ``BAD_LENGTH``,
    ``BAD_CRC``, ``MALFORMED``, ``TRUNCATED``; ``data`` holds the discarded bytes. Two errors are
    equal when kind and bytes are.
    """

    GARBAGE = "garbage"
    BAD_ID = "bad_id"
    BAD_LENGTH = "bad_length"
    BAD_CRC = "bad_crc"
    MALFORMED = "malformed"
    TRUNCATED = "truncated"

    def __init__(self, kind: str, data: bytes, detail: str = "") -> None:
        self.kind = kind
        self.data = bytes(data)
        self.detail = detail
        preview = self.data[:16].hex(" ") + (" …" if len(self.data) > 16 else "")
        reason = f"{kind} ({detail})" if detail else kind
        super().__init__(f"{reason}: discarded {len(self.data)} bytes: {preview}")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, DecodeError):
            return NotImplemented
        return (self.kind, self.data) == (other.kind, other.data)

    def __hash__(self) -> int:
        return hash((self.kind, self.data))

    def __repr__(self) -> str:
        return f"DecodeError({self.kind!r}, {self.data!r})"

    def __reduce__(self) -> tuple[type[DecodeError], tuple[str, bytes, str]]:
        return DecodeError, (self.kind, self.data, self.detail)


Decoded = InstructionPacket | StatusPacket | DecodeError


class PacketDecoder:
    """Turns a byte stream into packets and :class:`DecodeError` reports.

    ``max_length`` is the largest LEN field taken as plausible (default 1024, as dynamixel-sdk);
    ``max_error_bytes`` bounds both the bytes one error report carries and the garbage held while
    waiting for the next header.
    """

    def __init__(self, *, max_length: int = MAX_LENGTH, max_error_bytes: int = 1024) -> None:
        if isinstance(max_length, bool) or not isinstance(max_length, int) or max_length < 4:
            raise ValueError(f"max_length: must be an integer >= 4, got {max_length!r}")
        if (
            isinstance(max_error_bytes, bool)
            or not isinstance(max_error_bytes, int)
            or max_error_bytes < 1
        ):
            raise ValueError(f"max_error_bytes: must be an integer >= 1, got {max_error_bytes!r}")
        self.max_length = max_length
        self.max_error_bytes = max_error_bytes
        self.bytes_decoded = 0
        """Bytes that formed packets so far."""
        self.bytes_discarded = 0
        """Bytes reported in :class:`DecodeError` results so far."""
        self._buf = bytearray()
        self._pos = 0  # first byte not yet decided
        self._run_start: int | None = None  # start of discarded bytes not yet reported
        self._run_kind = DecodeError.GARBAGE
        self._run_detail = ""

    @property
    def pending(self) -> int:
        """Bytes held until more arrive (a partial frame, or garbage not reported yet)."""
        start = self._pos if self._run_start is None else self._run_start
        return len(self._buf) - start

    def feed(self, data: bytes | bytearray | memoryview) -> list[Decoded]:
        """Add bytes; return the packets and errors they complete, in stream order."""
        self._buf += data
        out: list[Decoded] = []
        self._process(out, final=False)
        return out

    def flush(self) -> list[Decoded]:
        """Decide every buffered byte now, as if the stream had ended; the decoder is then empty."""
        out: list[Decoded] = []
        self._process(out, final=True)
        return out

    def reset(self) -> None:
        """Forget buffered bytes without reporting them (counters are kept)."""
        self._buf.clear()
        self._pos = 0
        self._run_start = None

    # -- internals ---------------------------------------------------------------------------

    def _open_run(self, start: int, kind: str, detail: str = "") -> None:
        if self._run_start is None:
            self._run_start = start
            self._run_kind = kind
            self._run_detail = detail

    def _close_run(self, out: list[Decoded], end: int) -> None:
        """Report the open run of discarded bytes up to ``end``, in pieces of at most the cap."""
        start = self._run_start
        if start is None:
            return
        cap = self.max_error_bytes
        while start < end:
            piece = self._buf[start : min(end, start + cap)]
            self._report(out, DecodeError(self._run_kind, piece, self._run_detail))
            start += len(piece)
        self._run_start = None

    def _report(self, out: list[Decoded], error: DecodeError) -> None:
        self.bytes_discarded += len(error.data)
        out.append(error)

    def _process(self, out: list[Decoded], *, final: bool) -> None:
        buf = self._buf
        while True:
            pos, n = self._pos, len(buf)
            if buf.startswith(HEADER, pos):
                self._close_run(out, pos)
                if not self._frame_at(out, pos, n, final=final):
                    break
                continue
            hit = buf.find(HEADER, pos + 1)
            if hit >= 0:
                self._open_run(pos, DecodeError.GARBAGE)
                self._pos = hit
                continue
            # No complete header ahead: the last three bytes may still begin one.
            settled = n if final else n - (len(HEADER) - 1)
            if pos < settled:
                self._open_run(pos, DecodeError.GARBAGE)
                self._pos = settled
            if final:
                self._close_run(out, n)
            else:
                self._report_whole_pieces(out)
            break
        self._compact()

    def _report_whole_pieces(self, out: list[Decoded]) -> None:
        """While waiting, report the open run's whole pieces; the rest stays open, same kind."""
        start = self._run_start
        if start is None:
            return
        cap = self.max_error_bytes
        while self._pos - start >= cap:
            piece = self._buf[start : start + cap]
            self._report(out, DecodeError(self._run_kind, piece, self._run_detail))
            start += cap
        self._run_start = start

    def _frame_at(self, out: list[Decoded], pos: int, n: int, *, final: bool) -> bool:
        """Handle the header at ``pos``; False when more bytes are needed."""
        buf = self._buf
        if n - pos < _HEADER_SIZE:
            return self._incomplete(pos, final)
        packet_id = buf[pos + 4]
        length = buf[pos + 5] | (buf[pos + 6] << 8)
        if packet_id in _INVALID_IDS:
            self._open_run(pos, DecodeError.BAD_ID, f"ID {packet_id} is never used")
            self._pos = pos + len(HEADER)
            return True
        if not _MIN_LENGTH <= length <= self.max_length:
            detail = f"LEN {length} outside {_MIN_LENGTH}..{self.max_length}"
            self._open_run(pos, DecodeError.BAD_LENGTH, detail)
            self._pos = pos + len(HEADER)
            return True
        end = pos + _HEADER_SIZE + length
        if n < end:
            return self._incomplete(pos, final)
        received = buf[end - 2] | (buf[end - 1] << 8)
        with memoryview(buf) as view:  # released before the buffer is resized
            computed = crc16(view[pos : end - 2])
        if received != computed:
            stop = self._resume_point(pos, end)
            detail = f"CRC {received:04X}, computed {computed:04X}"
            self._report(out, DecodeError(DecodeError.BAD_CRC, buf[pos:stop], detail))
            self._pos = stop
            return True
        body = unstuff(buf[pos + _HEADER_SIZE : end - 2])
        if body[0] == Instruction.STATUS:
            if len(body) < 2:
                detail = "status packet without its error byte"
                self._report(out, DecodeError(DecodeError.MALFORMED, buf[pos:end], detail))
                self._pos = end
                return True
            packet: InstructionPacket | StatusPacket = StatusPacket(packet_id, body[1], body[2:])
        else:
            packet = InstructionPacket(packet_id, body[0], body[1:])
        self.bytes_decoded += end - pos
        out.append(packet)
        self._pos = end
        return True

    def _resume_point(self, pos: int, end: int) -> int:
        """Where to go on after the bad frame [pos, end): the first header that starts inside it.

        A header may also start in the frame's last bytes and run past its end; the normal scan
        then decides, once enough bytes are there, whether it really is one.
        """
        buf = self._buf
        inner = buf.find(HEADER, pos + 1, end)
        if inner >= 0:
            return inner
        for size in range(len(HEADER) - 1, 0, -1):
            if buf[end - size : end] == HEADER[:size]:
                return end - size
        return end

    def _incomplete(self, pos: int, final: bool) -> bool:
        if not final:
            return False
        self._open_run(pos, DecodeError.TRUNCATED, "the stream ended inside this frame")
        self._pos = pos + len(HEADER)
        return True

    def _compact(self) -> None:
        start = self._pos if self._run_start is None else self._run_start
        if start:
            del self._buf[:start]
            self._pos -= start
            if self._run_start is not None:
                self._run_start -= start


def decode_packet(frame: bytes | bytearray | memoryview) -> InstructionPacket | StatusPacket:
    """The one packet that ``frame`` is exactly; :class:`DecodeError` if it is anything else."""
    decoder = PacketDecoder()
    results = decoder.feed(frame) + decoder.flush()
    for item in results:
        if isinstance(item, DecodeError):
            raise item
    if len(results) != 1:
        raise DecodeError(DecodeError.MALFORMED, bytes(frame), f"{len(results)} packets in frame")
    return results[0]  # type: ignore[return-value]
