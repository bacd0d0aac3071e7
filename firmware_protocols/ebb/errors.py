"""The EBB's error replies (reference: "Returned Errors"; firmware 3.0 ``UBW.c``).

In legacy response mode an error line is the text below followed by ``<CR><NL>``, and no
``OK<CR><NL>`` follows it in firmware 3.0.3 (``CheckForAndPrintErrors``; the reference says one
does): :func:`.commands.format_error` gives the exact bytes.
"""

from __future__ import annotations

#: ``!1``: HM/SM/XM step rate outside its range.
STEP_RATE_INVALID = b"!1 Err: Invalid step rate"
#: ``!3``: the receive buffer overflowed (a line longer than the 256-byte limit).
RX_BUFFER_OVERRUN = b"!3 Err: RX Buffer overrun"
#: ``!4``: a required parameter is absent.
MISSING_PARAMETER = b"!4 Err: Missing parameter(s)"
#: ``!6``: a parameter is outside its documented range.
INVALID_PARAMETER = b"!6 Err: Invalid parameter value"
#: ``!7``: characters after the last parameter.
EXTRA_PARAMETER = b"!7 Err: Extra parameter"


def unknown_command(name: bytes) -> bytes:
    """``!8``: the error line for a command name the firmware does not know."""
    return b"!8 Err: Unknown command '" + name + b":" + name.hex().upper().encode() + b"'"


class EBBCommandError(ValueError):
    """A command the EBB rejects; ``reply`` is the firmware's error line (without line ending)."""

    def __init__(self, reply: bytes, detail: str = "") -> None:
        text = reply.decode("ascii", "replace")
        super().__init__(f"{text} ({detail})" if detail else text)
        self.reply = reply
        self.detail = detail


class MoveTooLong(ValueError):
    """A low-level move that never ends, or runs longer than the per-tick model materialises."""
