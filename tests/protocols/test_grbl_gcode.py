"""Host-side G-code formatting for Grbl 1.1: exact output, refusals, and read-back by Grbl's reader.

Oracle for the property tests: an independent model of Grbl's ``read_float`` (sign, digits with
one decimal point, first 8 digits kept) written with regular expressions and exact decimals.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.grbl import (
    MAX_LINE,
    dwell,
    fixed,
    jog,
    make_line,
    move,
    parse_line,
    read_float,
    setting,
    spindle_off,
    spindle_on,
    word,
)
from firmware_protocols.grbl.messages import Error


def grbl_number(text: str) -> tuple[Fraction, int] | None:
    """Independent oracle of Grbl's number reader: exact value and end index, or None."""
    match = re.match(r"([+-]?)(\d*)(?:\.(\d*))?", text)
    whole, fraction = match[2], match[3] or ""
    digits = whole + fraction
    if not digits:
        return None
    kept = digits[:8]
    value = Fraction(Decimal(kept)) * Fraction(10) ** (len(whole) - len(kept))
    return (-value if match[1] == "-" else value), match.end()


FIXED = [
    (0, 3, "0"),
    (0.0, 3, "0"),
    (-0.0, 3, "0"),
    (1, 3, "1"),
    (10.5, 3, "10.5"),
    (-3.0, 3, "-3"),
    (2.50, 3, "2.5"),
    (100, 3, "100"),
    (100.0, 0, "100"),
    (0.1, 3, "0.1"),
    (0.0005, 3, "0.001"),  # 0.0005 is a little above 5e-4 in binary
    (0.00049, 3, "0"),
    (-0.0002, 3, "0"),  # no "-0"
    (-0.0006, 3, "-0.001"),
    (1e-7, 3, "0"),
    (1e-7, 7, "0.0000001"),
    (123.456789, 3, "123.457"),
    (123.456789, 1, "123.5"),
    (2.5, 0, "2"),  # ties to even on the exact value
    (3.5, 0, "4"),
    (6000, 3, "6000"),
    (60 / 0.007, 3, "8571.429"),
    (99999.999, 3, "99999.999"),
    (-12345.678, 3, "-12345.678"),
    (1e7, 0, "10000000"),
    (np.float64(1.25), 3, "1.25"),
    (np.float32(0.1), 3, "0.1"),
    (np.int64(-7), 3, "-7"),
]


@pytest.mark.parametrize(("value", "decimals", "expected"), FIXED)
def test_fixed_exact_output(value: float, decimals: int, expected: str) -> None:
    assert fixed(value, decimals) == expected


@pytest.mark.parametrize(
    ("value", "decimals", "message"),
    [
        (math.nan, 3, "not a finite number: nan"),
        (math.inf, 3, "not a finite number: inf"),
        (-math.inf, 3, "not a finite number: -inf"),
        (10**400, 0, "needs more than 8 digits; Grbl reads 8"),
        (True, 3, "not a number: True"),
        ("1", 3, "not a number: '1'"),
        (None, 3, "not a number: None"),
        (1.0, -1, "decimals: must be an integer from 0 to 8, got -1"),
        (1.0, 9, "decimals: must be an integer from 0 to 8"),
        (1.0, 1.5, "decimals: must be an integer"),
        (123456.789, 3, "123456.789 needs 9 digits at 3 decimals; Grbl reads 8"),
        (1e300, 3, "needs 301 digits"),
        (123456789, 0, "needs 9 digits"),
        (0.00000001, 8, "needs 9 digits"),
    ],
)
def test_fixed_refuses(value: object, decimals: object, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        fixed(value, decimals)  # type: ignore[arg-type]


def test_fixed_never_uses_exponent_notation() -> None:
    for value in (1e-5, 1.5e-4, 12345678.0, 1e7, -2.5e-3):
        text = fixed(value, 3)
        assert "e" not in text.lower(), text


@given(
    st.floats(allow_nan=False, allow_infinity=False),
    st.integers(min_value=0, max_value=7),
)
def test_fixed_reads_back_with_grbl_reader(value: float, decimals: int) -> None:
    try:
        text = fixed(value, decimals)
    except ValueError as error:
        assert "digits" in str(error)
        assert abs(value) >= 10 ** (8 - decimals) - 10**-decimals  # only when Grbl would cut
        return
    assert re.fullmatch(r"-?\d+(\.\d*[1-9])?", text), text
    assert text != "-0"
    oracle, end = grbl_number(text)
    assert end == len(text)
    assert abs(oracle - Fraction(value)) <= Fraction(1, 2 * 10**decimals)
    parsed, end = read_float(text)
    assert end == len(text)
    assert Fraction(parsed) == Fraction(float(oracle))


@given(st.text(alphabet="0123456789.+-X", max_size=20), st.integers(min_value=0, max_value=3))
def test_read_float_matches_independent_oracle(text: str, start: int) -> None:
    result = read_float(text, start)
    expected = grbl_number(text[start:])
    if expected is None:
        assert result is None
    else:
        value, end = result
        assert end == start + expected[1]
        assert value == float(expected[0])


@pytest.mark.parametrize(
    ("text", "value", "end"),
    [
        ("1", 1.0, 1),
        ("-1.5X", -1.5, 4),
        ("+.5", 0.5, 3),
        ("5.", 5.0, 2),
        ("1.2.3", 1.2, 3),
        ("1e3", 1.0, 1),  # no exponent: 'e' ends the number
        ("123456789", 123456780.0, 9),  # ninth digit dropped
        ("1.23456789", 1.2345678, 10),
        ("0.0000001", 1e-7, 9),
        ("-0", -0.0, 2),
    ],
)
def test_read_float_table(text: str, value: float, end: int) -> None:
    assert read_float(text) == (value, end)


@pytest.mark.parametrize("text", ["", "-", "+", ".", "-.", "X1", "e3", "--1"])
def test_read_float_without_digits(text: str) -> None:
    assert read_float(text) is None


def test_word() -> None:
    assert word("X", 1.5) == "X1.5"
    assert word("F", 6000) == "F6000"
    assert word("P", 0.25, 2) == "P0.25"
    with pytest.raises(ValueError, match=r"^X: not a finite number: nan$"):
        word("X", math.nan)
    for letter in ("x", "XY", "", "1", 5):
        with pytest.raises(ValueError, match="letter: must be one of A to Z"):
            word(letter, 1)  # type: ignore[arg-type]


LINES = [
    (move(x=10.5, y=-3, feed=6000), "G1X10.5Y-3F6000\n"),
    (move(x=0, y=0, rapid=True), "G0X0Y0\n"),
    (move(z=-1.25), "G1Z-1.25\n"),
    (move(1, 2, 3, feed=100.5, decimals=1), "G1X1Y2Z3F100.5\n"),
    (move(x=1 / 3, y=2 / 3, feed=60 / 0.01), "G1X0.333Y0.667F6000\n"),
    (move(y=-0.0001, feed=1), "G1Y0F1\n"),
    (jog(x=1, feed=100), "$J=G91X1F100\n"),
    (jog(x=5, y=5, feed=1000, incremental=False), "$J=G90X5Y5F1000\n"),
    (dwell(0.25), "G4P0.25\n"),
    (dwell(0), "G4P0\n"),
    (spindle_on(), "M3\n"),
    (spindle_on(1000), "M3S1000\n"),
    (spindle_on(12.7, decimals=1), "M3S12.7\n"),
    (spindle_off(), "M5\n"),
    (setting(110, 6000), "$110=6000\n"),
    (setting(11, 0.01), "$11=0.01\n"),
    (make_line("G21", "G90", "G94"), "G21G90G94\n"),
    (make_line("G93"), "G93\n"),
]


@pytest.mark.parametrize(("line", "expected"), LINES)
def test_exact_lines(line: str, expected: str) -> None:
    assert line == expected


@pytest.mark.parametrize(("line", "expected"), LINES)
def test_lines_are_accepted_by_grbl_parser(line: str, expected: str) -> None:
    """Every built line reads back as words (or a setting/jog) with no error."""
    assert line.isascii() and line.endswith("\n") and line.count("\n") == 1
    assert not isinstance(parse_line(line), Error)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: move(), "move: give at least one of x, y, z"),
        (lambda: move(feed=100), "move: give at least one of x, y, z"),
        (lambda: move(x=1, feed=0), "F: must be > 0, got 0"),
        (lambda: move(x=1, feed=0.0001), "F: must be > 0, got 0.0001"),
        (lambda: move(x=1, feed=-5), "F: must be > 0, got -5"),
        (lambda: move(x=math.nan), "X: not a finite number: nan"),
        (lambda: move(x=1, y=math.inf), "Y: not a finite number: inf"),
        (lambda: move(x=1, feed=math.nan), "F: not a finite number: nan"),
        (lambda: move(x=123456.789), "X: 123456.789 needs 9 digits"),
        (lambda: jog(feed=100), "jog: give at least one of x, y, z"),
        (lambda: jog(x=1, feed=0), "F: must be > 0"),
        (lambda: dwell(-1), "P: must be >= 0, got -1"),
        (lambda: dwell(math.nan), "P: not a finite number: nan"),
        (lambda: spindle_on(-1), "S: must be >= 0, got -1"),
        (lambda: setting(300, 1), "number: must be an integer from 0 to 255, got 300"),
        (lambda: setting(True, 1), "number: must be an integer"),
        (lambda: setting(100, -80), "$100: must be >= 0, got -80"),
    ],
)
def test_builders_refuse(build, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        build()


def test_max_line_counts_the_newline() -> None:
    assert MAX_LINE == 80
    longest = "G1X" + "1" * (MAX_LINE - 4)  # 79 characters
    assert make_line(longest) == longest + "\n"
    assert len(make_line(longest)) == MAX_LINE
    assert not isinstance(parse_line(longest), Error)  # Grbl keeps 79 characters
    with pytest.raises(ValueError, match="line: 81 bytes with its newline, Grbl takes at most 80"):
        make_line(longest + "1")
    assert parse_line(longest + "1") == Error(11)  # and the device agrees


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "line: empty"),
        ("G1X1\n", "character 4 is '\\n', not printable ASCII"),
        ("G1X1\r", "not printable ASCII"),
        ("G1\tX1", "not printable ASCII"),
        ("G1X1é", "not printable ASCII"),
        ("G1X1 (why?)", "character 9 is '?', which Grbl takes as a real-time command"),
        ("M3!", "real-time command"),
        ("G4P1~", "real-time command"),
    ],
)
def test_make_line_refuses(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        make_line(text)
