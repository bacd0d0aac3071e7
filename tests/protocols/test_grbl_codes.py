"""Grbl 1.1h constants: code tables, real-time bytes, sizes; and the package's dependencies.

Facts from the Grbl 1.1h firmware (report.h, config.h, serial.h, planner.h, protocol.h) and the
status reports of its transcripts (``Bf:15,128`` when idle).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import firmware_protocols.grbl as grbl
from firmware_protocols.grbl import (
    ALARMS,
    BLOCK_BUFFER_SIZE,
    ERRORS,
    LINE_BUFFER_SIZE,
    PLANNER_BLOCKS,
    RX_BUFFER_SIZE,
    SETTINGS,
    Realtime,
    State,
    is_realtime_byte,
    parse_message,
)
from firmware_protocols.grbl.codes import HELP, MSG_ALARM_LOCK, MSG_UNLOCKED, setting_decimals


def test_code_tables() -> None:
    assert sorted(ERRORS) == [*range(1, 18), *range(20, 39)]
    assert sorted(ALARMS) == list(range(1, 11))
    assert ERRORS[20] == "unsupported G-code command"
    assert ERRORS[22] == "undefined feed rate"
    assert ERRORS[9] == "G-code locked out in Alarm or Jog state"
    assert all(text and text == text.strip() for text in [*ERRORS.values(), *ALARMS.values()])


def test_sizes() -> None:
    assert (RX_BUFFER_SIZE, BLOCK_BUFFER_SIZE, PLANNER_BLOCKS, LINE_BUFFER_SIZE) == (
        128,
        16,
        15,
        80,
    )
    idle = parse_message("<Idle|MPos:50.000,0.000,0.000|Bf:15,128|FS:0,0|Pn:PXYZRHS>")
    assert idle.buffer == (PLANNER_BLOCKS, RX_BUFFER_SIZE)


def test_realtime_bytes() -> None:
    assert bytes([Realtime.STATUS_REPORT]) == b"?"
    assert bytes([Realtime.FEED_HOLD]) == b"!"
    assert bytes([Realtime.CYCLE_START]) == b"~"
    assert Realtime.SOFT_RESET == 0x18
    assert Realtime.JOG_CANCEL == 0x85
    assert Realtime.SAFETY_DOOR == 0x84
    overrides = [r for r in Realtime if 0x90 <= r <= 0x9F]
    assert [int(r) for r in overrides] == [*range(0x90, 0x98), *range(0x99, 0x9F)]
    assert all(is_realtime_byte(r) for r in Realtime)
    intercepted = [b for b in range(256) if is_realtime_byte(b)]
    assert intercepted == [0x18, 0x21, 0x3F, 0x7E, *range(0x80, 0x100)]


def test_states_and_texts() -> None:
    assert [s.value for s in State] == [
        "Idle",
        "Run",
        "Hold",
        "Jog",
        "Alarm",
        "Door",
        "Check",
        "Home",
        "Sleep",
    ]
    assert parse_message(f"[MSG:{MSG_ALARM_LOCK}]").text == "'$H'|'$X' to unlock"
    assert parse_message(f"[MSG:{MSG_UNLOCKED}]").text == "Caution: Unlocked"
    assert HELP.startswith("$$ $# $G $I $N") and HELP.endswith("ctrl-x")


def test_settings_table() -> None:
    assert sorted(SETTINGS)[:8] == [0, 1, 2, 3, 4, 5, 6, 10]
    assert [n for n in SETTINGS if n >= 100] == [
        100,
        101,
        102,
        110,
        111,
        112,
        120,
        121,
        122,
        130,
        131,
        132,
    ]
    assert [setting_decimals(n) for n in (0, 10, 11, 13, 30, 31, 100, 122)] == [
        0,
        0,
        3,
        0,
        0,
        0,
        3,
        3,
    ]


def test_only_standard_library_imports() -> None:
    package = Path(grbl.__file__).parent
    for path in sorted(package.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                assert top in sys.stdlib_module_names or top == "__future__", (path.name, name)


def test_public_names() -> None:
    assert sorted(grbl.__all__) == sorted(set(grbl.__all__))
    for name in grbl.__all__:
        assert hasattr(grbl, name), name
