"""The EBB command set: the reference's example lines, the firmware's error replies, exact reply
bytes in legacy mode, round trips of the formatters, and the firmware feature table."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocols.ebb.commands import (
    FIFO_BOOT_DEPTH,
    FIFO_MAX_DEPTH,
    MIN_SUPPORTED,
    QU_VALUES,
    SPECS,
    Command,
    Firmware,
    GeneralStatus,
    Kind,
    LineReader,
    Reply,
    ReplyError,
    UnsupportedCommand,
    format_command,
    format_error,
    format_reply,
    nickname_shown,
    parse_command,
    read_reply,
)
from firmware_protocols.ebb.errors import EBBCommandError
from firmware_protocols.ebb.motion import Move

# Every command line of the reference ("EBB Command Set, Firmware v3.0+") for a modelled command,
# as printed in its section's examples and text.
REFERENCE_EXAMPLES = [
    b"EM,1,0",
    b"EM,2",
    b"EM,3,3",
    b"EM,0,1",
    b"EM,0,0",
    b"EM,3,1",
    b"LM,3865471,60,1732,0,0,0",
    b"LM,33865471,1000,0,0,0,0",
    b"LM,85899346,10,0,17180814,2,0",
    b"LM,85899346,500,0,85899346,250,0",
    b"LM,17180814,6,0,57266231,20,0",
    b"LM,42950000,50,13400,0,0,0",
    b"LM,17179000,75,-687,8592000,75,687",
    b"LT,10169,3865471,1732,0,0,3",
    b"LT,25000,33865471,0,0,0",
    b"LT,12500,17179000,-687,8592000,687",
    b"SC,4,8000",
    b"SC,1,1",
    b"SM,1000,250,-766",
    b"XM,1000,550,-1234",
    b"SP,1",
    b"SR,60000,1",
    b"S2,24000,6",
    b"S2,0,5",
    b"S2,10000,5,0,100",
    b"S2,27500,5,50,10",
    b"CU,10,1",
    b"CU,52,0",
    b"CU,53,1",
    b"CU,51,4",
    b"CU,52,164",
    b"CU,51,164",
    b"CU,51,0",
    b"CU,60,404",
    b"R",
    b"V",
    b"QS",
    b"QG",
    b"QU,2",
    b"QU,3",
]


@pytest.mark.parametrize("line", REFERENCE_EXAMPLES)
@pytest.mark.parametrize("end", [b"\r", b"\n", b"\r\n", b""])
def test_reference_examples_parse(line: bytes, end: bytes) -> None:
    cmd = parse_command(line + end)
    assert cmd.extra is False
    assert format_command(cmd.name, *cmd.params) == line + b"\r"


def test_parsed_values_and_case() -> None:
    assert parse_command(b"lm,17179000,75,-687,8592000,75,687\r") == Command(
        "LM", (17179000, 75, -687, 8592000, 75, 687)
    )
    assert parse_command(b"qu,2") == Command("QU", (2,))
    assert parse_command(b"LT,10169,3865471,1732,0,0,3").move() == Move(
        "LT", (3865471, 0), (1732, 0), ticks=10169, clear=3
    )
    assert parse_command(b"T3,100,1,2,3,4,5,6").move() == Move(
        "T3", (1, 4), (2, 5), (3, 6), ticks=100
    )
    assert parse_command(b"LM,1,2,3,4,5,6,2").move() == Move(
        "LM", (1, 4), (3, 6), steps=(2, 5), clear=2
    )
    with pytest.raises(ValueError, match="not a low-level move"):
        parse_command(b"SM,10,1").move()


ERRORS = [
    (b"SM,100", b"!4 Err: Missing parameter(s)"),
    (b"SM,100,", b"!4 Err: Missing parameter(s)"),
    (b"SM,100A", b"!5 Err: Need comma next, found: 'A'"),
    (b"SMX,1", b"!5 Err: Need comma next, found: 'X'"),
    (b"SP,-1", b"!6 Err: Invalid parameter value"),
    (b"B", b"!8 Err: Unknown command 'B:42'"),
    (b"bb,1", b"!8 Err: Unknown command 'BB:4242'"),
    (b"T,250,0", b"!8 Err: Unknown command 'T:54'"),  # removed in 3.0
    (b"PG,1", b"!8 Err: Unknown command 'PG:5047'"),
    (b"LM,1,0,2,0,0,0", b"!6 Err: Invalid parameter value"),  # no axis can move
    (b"LM,0,1,0,0,0,0,0", b"!6 Err: Invalid parameter value"),
    (b"LM,-5,-10,0,0,0,0", b"!6 Err: Invalid parameter value"),  # negative steps and rate
    (b"LT,0,1,0,1,0", b"!6 Err: Invalid parameter value"),
    (b"T3,0,1,0,0,1,0,0", b"!6 Err: Invalid parameter value"),
    (b"LT,4294967296,1,0,1,0", b"!6 Err: Invalid parameter value"),  # 10 digits wrap to 0
    (b"SM,0,10", b"!6 Err: Invalid parameter value"),
    (b"SM,10,10,10,4", b"!6 Err: Invalid parameter value"),
    (b"XM,0,10,10", b"!6 Err: Invalid parameter value"),
    (b"SM,1,1000", b"!0 Err: <axis1> step rate too high"),
    (b"SM,1,0,1000", b"!0 Err: <axis2> step rate too high"),
    (b"SM,100000000,1", b"!0 Err: <axis1> step rate too slow"),
    (b"XM,1,13,13", b"!0 Err: <axis1> step rate too high"),  # motor 1 gets A+B = 26
    (b"XM,100000000,1,0", b"!0 Err: <axis1> step rate too slow"),
    (b"SM,1,26", b"!0 Err: <axis1> step rate too high"),  # 25 steps/ms is the most
    (b"SM,85899360,1", b"!0 Err: <axis1> step rate too slow"),
    (b"SM,257698040,3", b"!0 Err: <axis1> step rate too slow"),  # 0.99999994 in float32
    (b"SR,-5", b"!6 Err: Invalid parameter value"),  # a sign on an unsigned parameter
    (b"CU,1,2", b"!6 Err: Invalid parameter value"),
    (b"CU,2,2", b"!6 Err: Invalid parameter value"),
    (b"CU,3,5", b"!6 Err: Invalid parameter value"),
    (b"CU,10,-1", b"!6 Err: Invalid parameter value"),
    (b"CU,7,0", b"!6 Err: Invalid parameter value"),
    (b"CU,1,32768", b"!6 Err: Invalid parameter value"),
    (b"CU,1,-32769", b"!6 Err: Invalid parameter value"),
    (b"CU,65536,1", b"!6 Err: Invalid parameter value"),
    (b"QU,7", b"!6 Err: Invalid parameter value"),
    (b"QU,256", b"!6 Err: Invalid parameter value"),
    (b"QU", b"!4 Err: Missing parameter(s)"),
    (b"S2,1000,25", b"!6 Err: Invalid parameter value"),
    (b"LM,2147483648,1,0,0,0,0", b"!6 Err: Invalid parameter value"),
    (b"LM,-2147483649,1,0,0,0,0", b"!6 Err: Invalid parameter value"),
    (b"EM,256", b"!6 Err: Invalid parameter value"),
    (b"X" * 256, b"!3 Err: RX Buffer overrun"),
]


@pytest.mark.parametrize(("line", "reply"), ERRORS)
def test_malformed_lines_give_the_firmware_error(line: bytes, reply: bytes) -> None:
    with pytest.raises(EBBCommandError) as caught:
        parse_command(line + b"\r")
    assert caught.value.reply == reply


def test_a_refused_parameter_says_why_beside_the_firmware_error() -> None:
    """The error a host sees names the firmware's reply, then what in the line was wrong."""
    with pytest.raises(EBBCommandError) as caught:
        parse_command(b"SR,-5\r")
    assert str(caught.value) == "!6 Err: Invalid parameter value (a negative unsigned parameter)"
    with pytest.raises(EBBCommandError) as caught:
        parse_command(b"EM,256\r")
    assert str(caught.value) == "!6 Err: Invalid parameter value (256 out of 0..255)"


def test_boundaries_accepted() -> None:
    assert parse_command(b"LM,-2147483648,1,0,0,0,0").params[0] == -(2**31)
    assert parse_command(b"LM,2147483647,1,0,0,0,0").params[0] == 2**31 - 1
    assert parse_command(b"LT,4294967295,1,0,1,0").params[0] == 2**32 - 1
    assert parse_command(b"SR,4294967297").params == (1,)  # read into 32 bits
    assert parse_command(b"CU,61,-32768").params == (61, -32768)
    assert parse_command(b"SC,255,65535").params == (255, 65535)
    assert parse_command(b"S2,0,24").params == (0, 24)
    assert parse_command(b"LM,0,-0,0,1,1,0").params[:2] == (0, 0)  # "-0" and "-" read as 0
    assert parse_command(b"SM,100,-").params == (100, 0)
    # SM/XM step rates in the firmware's 32-bit floats: 25 steps/ms is exactly 2**31 per tick.
    assert parse_command(b"SM,1,25,-25").params == (1, 25, -25)
    assert parse_command(b"SM,85899344,1").params == (85899344, 1)
    assert parse_command(b"SM,85899346,1").params == (85899346, 1)  # float32(85899346) == 85899344
    assert parse_command(b"SM,10,10,10,3").params == (10, 10, 10, 3)
    assert parse_command(b"SM,100,5,").params == (100, 5)
    assert parse_command(b"XM,1,12,-13").params == (1, 12, -13)
    assert parse_command(b"SM,100000000,0,0").params == (100000000, 0, 0)  # a delay
    assert parse_command(b"CU,4,100").params == (4, 100)  # the firmware clamps it to 32
    # An 11th digit is not read: it is left over, the command runs, then "!7 Extra parameter".
    assert parse_command(b"SR,12345678901") == Command("SR", (1234567890,), extra=True)


def test_line_of_255_characters_fits() -> None:
    line = b"SC,4," + b"0" * 249 + b"7"
    assert len(line) == 255
    # Ten digits are read, the rest is left over: runs, then !7, and no overrun.
    assert parse_command(line).extra is True


def test_limit_checks_off() -> None:
    assert parse_command(b"LM,1,0,2,0,0,0", limit_checks=False).params == (1, 0, 2, 0, 0, 0)
    assert parse_command(b"LT,0,1,0,1,0", limit_checks=False).params[0] == 0
    assert parse_command(b"SM,0,10", limit_checks=False).params == (0, 10)
    with pytest.raises(EBBCommandError):  # the LM sign rule is checked regardless
        parse_command(b"LM,-5,-10,0,0,0,0", limit_checks=False)


def test_not_modelled_and_not_lines() -> None:
    with pytest.raises(UnsupportedCommand):
        parse_command(b"TP\r")
    with pytest.raises(UnsupportedCommand, match="ST without"):
        parse_command(b"ST\r")  # the firmware clears the name and answers OK and an error
    with pytest.raises(UnsupportedCommand, match="ST without"):
        parse_command(b"STx\r")
    with pytest.raises(UnsupportedCommand):
        parse_command(b"CU,250,1\r")
    with pytest.raises(UnsupportedCommand):
        parse_command(b"CU,257,0\r")
    with pytest.raises(ValueError, match="empty"):
        parse_command(b"\r\n")
    with pytest.raises(ValueError, match="more than one line"):
        parse_command(b"V\rV\r")


def test_empty_line_is_refused_with_its_message() -> None:
    """A bare terminator is refused with the exact message ``an empty line``."""
    for line in (b"\r\n", b"\r", b"\n", b""):
        with pytest.raises(ValueError) as info:
            parse_command(line)
        assert str(info.value) == "an empty line"


def test_extra_characters_run_then_report() -> None:
    assert parse_command(b"SM,1,1,1,0,0\r") == Command("SM", (1, 1, 1, 0), extra=True)
    assert parse_command(b"QS,1\r") == Command("QS", (), extra=True)
    assert parse_command(b"V,100\r").extra is True
    assert parse_command(b"R,1\r").extra is False  # reset ignores what follows
    cmd = parse_command(b"LM,1,1,0,0,0,0X\r")
    assert cmd == Command("LM", (1, 1, 0, 0, 0, 0), extra=True)
    assert format_reply(cmd) == b"OK\r\n!7 Err: Extra parameter\r\n"


REPLIES = [
    (b"CS", (), b"OK\r\n"),
    (b"LM,1,1,0,0,0,0", (), b"OK\r\n"),
    (b"V", ("EBBv13_and_above EB Firmware Version 3.0.3",),
     b"EBBv13_and_above EB Firmware Version 3.0.3\r\n"),
    (b"QS", (1421, -429), b"1421,-429\n\rOK\r\n"),
    (b"QM", (1, 1, 0, 1), b"QM,1,1,0,1\n\r"),
    (b"QB", (1,), b"1\r\nOK\r\n"),
    (b"QG", (0x3E,), b"3E\r\n"),
    (b"QG", (5,), b"05\r\n"),
    (b"QP", (1,), b"1\n\rOK\r\n"),
    (b"QE", (16, 16), b"16,16\n\rOK\r\n"),
    (b"ES", (0,), b"0\n\rOK\r\n"),
    (b"ES,1", (1,), b"1\n\rOK\r\n"),
    (b"QU,1", (0xA,), b"QU,0A\r\nOK\r\n"),
    (b"QU,2", (32,), b"QU,32\r\nOK\r\n"),
    (b"QU,3", (1,), b"QU,1\r\nOK\r\n"),
    (b"QU,4", (0xE71,), b"QU,E71\r\nOK\r\n"),
    (b"QU,5", (0x71,), b"QU,071\r\nOK\r\n"),
    (b"QU,6", (3,), b"QU,3\r\nOK\r\n"),
    (b"QU,61", (65534,), b"QU,65534\r\nOK\r\n"),
    (b"QU,200", (5, 2**31 - 1), b"QU,5,2147483647\r\nOK\r\n"),
    (b"RB", (), b""),
    (b"EM,1", (), b""),  # 3.0.3 returns before answering when Enable2 is absent
    (b"EM,1,1", (), b"OK\r\n"),
    (b"CU,10,1", (), b"\n"),
    (b"CU,10,0", (), b"OK\r\n"),
    (b"QR", (1,), b"1\n\rOK\r\n"),
    (b"QT", (b"East EBB",), b"East EBB\r\nOK\r\n"),
    (b"QT", (b"",), b"\r\nOK\r\n"),  # no nickname: an empty line
    (b"ST,East EBB", (), b"OK\r\n"),
]  # fmt: skip


def test_nicknames_as_st_reads_them_and_qt_prints_them() -> None:
    assert parse_command(b"st,East EBB\r") == Command("ST", text=b"East EBB")
    assert parse_command(b"ST,\r") == Command("ST", text=b"")  # clears the name
    # 16 bytes at most, up to a comma; what is left is an extra parameter (!7 after OK).
    long = parse_command(b"ST,abcdefghijklmnopq\r")
    assert long.text == b"abcdefghijklmnop" and long.extra
    assert parse_command(b"ST,ab,cd\r") == Command("ST", extra=True, text=b"ab")
    assert format_reply(long) == b"OK\r\n!7 Err: Extra parameter\r\n"
    # QT prints a stored name only when it starts with printable ASCII other than a space.
    qt = parse_command(b"QT\r")
    assert format_reply(qt, b" lead") == b"\r\nOK\r\n"
    assert format_reply(qt, b"\xe9t\xe9") == b"\r\nOK\r\n"
    assert format_reply(qt, b"t\xe9 x") == b"t\xe9 x\r\nOK\r\n"
    assert read_reply(qt, b"t\xe9 x\r\nOK\r\n").values == (b"t\xe9 x",)


@pytest.mark.parametrize(("line", "values", "reply"), REPLIES)
def test_reply_bytes_and_reading_them_back(line: bytes, values: tuple, reply: bytes) -> None:
    cmd = parse_command(line)
    assert format_reply(cmd, *values) == reply
    for cut in range(len(reply)):
        assert read_reply(cmd, reply[:cut]) is None, reply[:cut]
    more = b"OK\r\n"  # the next command's reply may already be there
    got = read_reply(cmd, reply + more)
    assert got is not None
    assert got.size == len(reply)
    assert got.check().values == values


def test_no_ok_mode() -> None:
    cmd = parse_command(b"QS")
    assert format_reply(cmd, 1, 2, ack=False) == b"1,2\n\r\r\n"
    assert format_reply(parse_command(b"CS"), ack=False) == b"\r\n"
    assert read_reply(cmd, b"1,2\n\r\r\n", ack=False).values == (1, 2)


ERROR_REPLIES = [
    (b"SM", b"!4 Err: Missing parameter(s)", b"!4 Err: Missing parameter(s)\r\n"),
    (b"QU", b"!6 Err: Invalid parameter value", b"QU,!6 Err: Invalid parameter value\r\n"),
    (b"SM", b"!0 Err: <axis2> step rate too slow",
     b"!0 Err: <axis2> step rate too slow\n\r\r\n"),
    (b"XX", b"!8 Err: Unknown command 'XX:5858'", b"!8 Err: Unknown command 'XX:5858'\r\n"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "error", "reply"), ERROR_REPLIES)
def test_error_replies(name: bytes, error: bytes, reply: bytes) -> None:
    assert format_error(error, name.decode()) == reply
    sent = {b"SM": Command("SM", (1, 1)), b"QU": Command("QU", (2,)), b"XX": Command("V")}[name]
    for cut in range(len(reply)):
        assert read_reply(sent, reply[:cut]) is None
    got = read_reply(sent, reply + b"OK\r\n")
    assert (got.error, got.size) == (error, len(reply))
    with pytest.raises(EBBCommandError) as caught:
        got.check()
    assert caught.value.reply == error


@pytest.mark.parametrize(
    ("cmd", "data"),
    [
        (Command("QP"), b"1\r\nOK\r\n"),  # QP ends <NL><CR>
        (Command("QS"), b"12,x\n\rOK\r\n"),
        (Command("QG"), b"3e\r\n"),  # upper-case hex
        (Command("CS"), b"KO\r\n"),
        (Command("QM"), b"QM,1,1,1\n\r"),
        (Command("V"), b"!8 Err: Unknown\n"),
        (Command("QU", (2,)), b"QU,\n"),  # a stray line feed right after the echo: at once
    ],
)
def test_replies_that_are_not_documented_are_refused(cmd: Command, data: bytes) -> None:
    with pytest.raises(ReplyError):
        read_reply(cmd, data)


def _params(name: str) -> st.SearchStrategy[tuple[int, ...]]:
    spec = SPECS[name]
    required = sum(1 for _, req in spec if req)
    return st.integers(required, len(spec)).flatmap(
        lambda n: st.tuples(*(st.integers(*kind.value) for kind, _ in spec[:n]))
    )


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(sorted(SPECS)).flatmap(lambda n: st.tuples(st.just(n), _params(n))))
def test_format_then_parse_round_trip(case: tuple[str, tuple[int, ...]]) -> None:
    name, params = case
    line = (",".join([name, *map(str, params)]) + "\r").encode()
    try:
        expected = parse_command(line)
    except (EBBCommandError, UnsupportedCommand) as refused:
        with pytest.raises(type(refused)):
            format_command(name, *params)
        return
    assert expected == Command(name, params)
    assert format_command(name.lower(), *params) == line


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(["LM", "LT", "T3"]),
    st.lists(st.integers(-(2**31), 2**31 - 1), min_size=6, max_size=6),
    st.integers(1, 2**32 - 1),
    st.integers(0, 3),
)
def test_move_lines_parse_back(command: str, v: list[int], ticks: int, clear: int) -> None:
    move = Move(command, (v[0], v[1]), (v[2], v[3]), (v[4], v[5]) if command == "T3" else (0, 0),
                steps=(v[4], v[5]) if command == "LM" else (0, 0),
                ticks=0 if command == "LM" else ticks, clear=clear)  # fmt: skip
    try:
        move.validate()
    except EBBCommandError:
        return
    assert parse_command(move.line()).move() == move


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(["QS", "QM", "QB", "QG", "QP", "QE", "ES", *(f"QU,{n}" for n in QU_VALUES)]),
    st.data(),
)
def test_query_replies_round_trip(line: str, data: st.DataObject) -> None:
    cmd = parse_command(line.encode())
    flag = st.integers(0, 1)
    values = {
        "QS": st.tuples(st.integers(*Kind.LONG.value), st.integers(*Kind.LONG.value)),
        "QM": st.tuples(flag, flag, flag, flag),
        "QG": st.tuples(st.integers(0, 255)),
        "QE": st.tuples(st.sampled_from([0, 1, 2, 4, 8, 16]), st.sampled_from([0, 1, 2, 4, 8, 16])),
    }.get(cmd.name, st.tuples(flag))
    if cmd.name == "QU":
        width = QU_VALUES[cmd.params[0]]
        count = 2 if cmd.params[0] == 200 else 1
        top = 16**width - 1 if width else 2**32 - 1
        values = st.tuples(*[st.integers(0, top)] * count)
    sent = data.draw(values)
    reply = format_reply(cmd, *sent)
    got = read_reply(cmd, reply + b"1,2\n\rOK\r\n")
    assert (got.values, got.size) == (sent, len(reply))


def test_general_status_bits() -> None:
    status = GeneralStatus.from_byte(0x3E)
    assert (status.button, status.pen_up, status.executing, status.motor1, status.motor2) == (
        True,
        True,
        True,
        True,
        True,
    )
    assert (status.limit_switch, status.power_lost, status.fifo) == (False, False, False)
    assert GeneralStatus.from_byte(0x81).limit_switch and GeneralStatus.from_byte(0x81).fifo
    assert GeneralStatus.from_byte(0x40).power_lost
    assert all(GeneralStatus.from_byte(b).byte() == b for b in range(256))
    for value in (256, -1):  # just beyond either end: refused, naming the value
        with pytest.raises(ReplyError, match=rf"^QG status {value}: not a byte$"):
            GeneralStatus.from_byte(value)


def test_firmware_from_version() -> None:
    fw = Firmware.from_version(b"EBBv13_and_above EB Firmware Version 3.0.3\r\n")
    assert (fw.board, fw.version, fw.supported) == ("EBBv13_and_above", (3, 0, 3), True)
    assert fw.has("T3") and fw.has("lt") and fw.has("QU")
    assert fw.max_fifo == FIFO_MAX_DEPTH == 32
    old = Firmware.from_version("EBBv13_and_above EB Firmware Version 2.8.1")
    assert not old.supported and old.has("LT") and old.has("QE") and not old.has("T3")
    assert old.max_fifo == FIFO_BOOT_DEPTH == 1
    assert not Firmware.from_version("EBBv13_and_above EB Firmware Version 2.6.5").has("LM")
    assert MIN_SUPPORTED == (3, 0, 0)
    assert Firmware.from_version("EBBv13_and_above EB Firmware Version 3.0.0").supported
    for bad in ("", "EBB 3.0.3", "EBBv13_and_above EB Firmware Version 3.0", "Grbl 1.1h"):
        with pytest.raises(ReplyError, match="not an EBB version string"):
            Firmware.from_version(bad)
    # A reply with a byte that is not ASCII (a garbled line) is quoted with it replaced.
    with pytest.raises(ReplyError, match=r"^V: '\ufffdBB 3\.0\.3' is not an EBB version string$"):
        Firmware.from_version(b"\xe9BB 3.0.3\r\n")


SINCE = [
    ("V", (1, 0, 0)), ("QP", (1, 9, 0)), ("QB", (1, 9, 2)), ("S2", (2, 2, 0)), ("ES", (2, 2, 7)),
    ("XM", (2, 3, 0)), ("QS", (2, 4, 3)), ("CS", (2, 4, 3)), ("QM", (2, 4, 4)), ("RB", (2, 5, 4)),
    ("SR", (2, 6, 0)), ("QG", (2, 6, 2)), ("HM", (2, 6, 2)), ("LM", (2, 7, 0)), ("LT", (2, 7, 0)),
    ("QE", (2, 8, 0)), ("QU", (3, 0, 0)), ("T3", (3, 0, 0)), ("QT", (2, 5, 4)), ("ST", (2, 5, 5)),
    ("QR", (2, 6, 0)),
]  # fmt: skip


@pytest.mark.parametrize(("name", "since"), SINCE)
def test_commands_from_their_documented_version(name: str, since: tuple[int, int, int]) -> None:
    major, minor, patch = since
    at = Firmware.from_version(f"EBBv13_and_above EB Firmware Version {major}.{minor}.{patch}")
    assert at.has(name)
    before = (major, minor, patch - 1) if patch else (major, minor - 1, 9) if minor else (0, 9, 9)
    older = Firmware.from_version(
        "EBBv13_and_above EB Firmware Version " + ".".join(map(str, before))
    )
    assert not older.has(name)


def test_format_command_refuses_what_the_firmware_would() -> None:
    assert format_command("sm", 1000, 250, -766) == b"SM,1000,250,-766\r"
    with pytest.raises(EBBCommandError, match="!4"):
        format_command("SM", 1000)
    with pytest.raises(ValueError, match="1 parameters, V takes 0"):
        format_command("V", 1)
    with pytest.raises(EBBCommandError, match="!6"):
        format_command("LT", -1, 1, 0, 1, 0)


def test_line_reader_cuts_like_the_firmware() -> None:
    reader = LineReader()
    assert reader.feed(b"\r\nV\r\nQS\rSM,1\x01,2\n\n") == [b"", b"V", b"QS", b"SM,1,2"]
    assert reader.feed(b"S M,1\r") == [b"S M,1"]  # a space is kept (and refused by the parser)
    assert reader.feed(b"QU,") == []
    assert reader.feed(b"2\r") == [b"QU,2"]
    assert reader.feed(b"\n\r\r") == []


# -- edges (issue 34: what a changed line would break) ---------------------------------------


def test_refusals_name_their_reason() -> None:
    cases = {
        b"SM,0,10": "!6 Err: Invalid parameter value (Duration 0)",
        b"S2,1000,25": "!6 Err: Invalid parameter value (S2 pin above 24)",
        b"SM,10,10,10,4": "!6 Err: Invalid parameter value (Clear above 3)",
        b"QU,7": "!6 Err: Invalid parameter value (QU,7)",
        b"CU,7,0": "!6 Err: Invalid parameter value (CU,7,0)",
    }
    for line, message in cases.items():
        with pytest.raises(EBBCommandError) as caught:
            parse_command(line)
        assert str(caught.value) == message


def test_xm_sums_its_axes_in_the_firmwares_32_bit_ints() -> None:
    # Motor 2 gets A - B = -2**31 - 1, which wraps to 2**31 - 1 steps: about 1.0 step per tick
    # over 10**8 ms, within the rate. Unwrapped, 3 * 2**31 - 1 steps would be too fast.
    assert parse_command(b"XM,100000000,-2147483648,1").params == (100000000, -(2**31), 1)
    # A + B = 2**31 wraps to -2**31: the same magnitude, checked as such.
    assert parse_command(b"XM,100000000,2147483647,1").params == (100000000, 2**31 - 1, 1)
    with pytest.raises(EBBCommandError, match="step rate too high"):
        parse_command(b"XM,80000000,2147483647,1")


def test_sm_without_a_second_axis_moves_only_the_first() -> None:
    # 2000 steps over 90 000 s: slow but within the rate; motor 2 has no steps, so no rate.
    assert parse_command(b"SM,90000000,2000").params == (90000000, 2000)
    with pytest.raises(EBBCommandError, match="axis2> step rate too slow"):
        parse_command(b"SM,90000000,2000,1")


def test_a_one_byte_reply_is_complete_when_it_is_the_whole_reply() -> None:
    # CU,10,1 (future syntax) is answered with a lone <NL>.
    assert read_reply(parse_command(b"CU,10,1"), b"\n") == Reply((), 1)
    # A QU reply is incomplete until its "QU," and more have come.
    assert read_reply(parse_command(b"QU,2"), b"Q") is None
    assert read_reply(parse_command(b"QU,2"), b"QU,") is None
    assert read_reply(parse_command(b"V"), b"!") is None
    # Two bytes that can no longer become an error line are refused at once, not waited on.
    for cmd in (b"V", b"QU,2"):
        with pytest.raises(ReplyError, match="a line ending out of place"):
            read_reply(parse_command(cmd), b"!\n")


def test_format_command_refuses_parameters_a_command_ignores() -> None:
    # R runs whatever follows it: a parameter given to R would be silently dropped.
    with pytest.raises(ValueError, match=r"1 parameters, R takes 0"):
        format_command("R", 5)
    assert format_command("R") == b"R\r"


def test_qt_shows_a_nickname_only_from_a_printable_first_byte() -> None:
    assert nickname_shown(b"!ok") == b"!ok"  # 33: the first printable after the space
    assert nickname_shown(b"\x7fok") == b"\x7fok"
    assert nickname_shown(b" ok") == b"" and nickname_shown(b"\x80ok") == b""
    assert nickname_shown(b"") == b""


def test_an_error_reply_has_no_values() -> None:
    reply = read_reply(parse_command(b"V"), b"!8 Err: Unknown command 'X:58'\r\n")
    assert reply == Reply((), 32, b"!8 Err: Unknown command 'X:58'")
    with pytest.raises(EBBCommandError, match="Unknown command"):
        reply.check()


def test_st_takes_the_name_up_to_the_first_comma() -> None:
    cmd = parse_command(b"ST,abc,def,ghi")
    assert cmd.text == b"abc" and cmd.extra


def test_a_line_starting_with_an_error_mark_that_is_no_error_is_named() -> None:
    with pytest.raises(ReplyError, match=r"^V: b'!x\\r\\n' is not an EBB error line$"):
        read_reply(parse_command(b"V"), b"!x\r\n")


def test_qt_answers_a_nickname_given_as_text_or_bytes_alike() -> None:
    qt = parse_command(b"QT")
    assert format_reply(qt, "abc") == format_reply(qt, b"abc") == b"abc\r\nOK\r\n"


def test_qt_with_no_nickname_given_answers_an_empty_line():
    """``QT`` on a board with no stored nickname prints an empty line, then ``OK``."""
    qt = parse_command(b"QT")
    assert format_reply(qt) == b"\r\nOK\r\n"
    assert format_reply(qt, ack=False) == b"\r\n\r\n"
    assert read_reply(qt, format_reply(qt)).values == (b"",)
