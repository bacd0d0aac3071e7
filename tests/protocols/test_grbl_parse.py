"""Device-side reading of received lines, checked against Grbl 1.1h.

Golden vectors: the (sent line, answer) pairs of serial transcripts recorded from the Grbl 1.1h
firmware (``grblsim_1.1h_*.log``), copied here as literals, and single cases traced through the
firmware's protocol.c, gcode.c and system.c.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.grbl import (
    Block,
    Error,
    Help,
    Home,
    ParserState,
    Restore,
    SetBuildInfo,
    SetSetting,
    SetStartupLine,
    Sleep,
    State,
    Step,
    ToggleCheckMode,
    Unlock,
    ViewBuildInfo,
    ViewParameters,
    ViewParserState,
    ViewSettings,
    ViewStartupLines,
    parse_line,
)


class Session:
    """Just enough of Grbl's main loop to replay a transcript: state, parser state, answers."""

    def __init__(self, state: State = State.IDLE) -> None:
        self.state = state
        self.parser = ParserState()

    def send(self, line: str) -> str:
        parsed = parse_line(line, self.state)
        if isinstance(parsed, Error):
            return f"error:{parsed.code}"
        if isinstance(parsed, Unlock) and self.state == State.ALARM:
            self.state = State.IDLE
        if isinstance(parsed, Block):
            step = self.parser.step(parsed)
            if isinstance(step, Error):
                return f"error:{step.code}"
            self.parser = step.state
            if step.jog:
                self.state = State.JOG  # the jog is still running when the next lines arrive
        return "ok"


# grblsim_1.1h_alarm.log: after a reset (Idle); the jog leaves Grbl in the Jog state.
ALARM_LOG = [
    ("G1 X1", "error:22"),
    ("G21 G90", "ok"),
    ("G1 X1 F0", "error:22"),
    ("G5 X1", "error:20"),
    ("$J=G91 X1 F100", "ok"),
    ("M3 S500", "error:9"),
    ("M5", "error:9"),
    ("G4 P0.1", "error:9"),
]
# grblsim_1.1h_errorline.log
ERRORLINE_LOG = [
    ("G21 G90 G94", "ok"),
    ("G1 X5 F600", "ok"),
    ("G1 Q5", "error:20"),
    ("G1 X0", "ok"),
]
# grblsim_1.1h_sendresp.log
SENDRESP_LOG = [
    ("G21 G90 G94", "ok"),
    ("G1 X10 Y0 F600", "ok"),
    ("G1 X10 Y10", "ok"),
    ("G1 X0 Y10", "ok"),
    ("G0 X0 Y0", "ok"),
]
# grblsim_1.1h_setup-plotter.log, in the Alarm state after a reset in motion.
SETUP_LOG = [
    ("$X", "ok"),
    ("$100=80", "ok"),
    ("$101=80", "ok"),
    ("$102=80", "ok"),
    ("$110=6000", "ok"),
    ("$111=6000", "ok"),
    ("$112=3000", "ok"),
    ("$120=1000", "ok"),
    ("$121=1000", "ok"),
    ("$122=1000", "ok"),
    ("$11=0.01", "ok"),
    ("$10=3", "ok"),
]
# grblsim_1.1h_reset.log, after the reset in motion (Alarm).
RESET_LOG = [("G1 X0 F300", "error:9"), ("$X", "ok")]


@pytest.mark.parametrize(
    ("state", "log"),
    [
        (State.IDLE, ALARM_LOG),
        (State.IDLE, ERRORLINE_LOG),
        (State.IDLE, SENDRESP_LOG),
        (State.ALARM, SETUP_LOG),
        (State.ALARM, RESET_LOG),
    ],
    ids=["alarm", "errorline", "sendresp", "setup-plotter", "reset"],
)
def test_transcripts(state: State, log: list[tuple[str, str]]) -> None:
    session = Session(state)
    assert [(line, session.send(line)) for line, _ in log] == log


def test_sendresp_positions() -> None:
    session = Session()
    for line, _ in SENDRESP_LOG[:3]:
        session.send(line)
    assert session.parser.position == (10.0, 10.0, 0.0)
    assert session.parser.feed_rate == 600.0


def test_setup_values() -> None:
    assert parse_line("$11=0.01", State.ALARM) == SetSetting(11, 0.01)
    assert parse_line("$110=6000") == SetSetting(110, 6000.0)


def block(text: str, commands: tuple[str, ...] = (), *words: tuple[str, float]) -> Block:
    return Block(text, commands, tuple(words), text.startswith("$"))


LINE_BUFFER = [
    ("", Block()),
    ("   ", Block()),
    ("\n", Block()),
    ("\r\n", Block()),
    ("(just a comment)", Block()),
    ("; to the end", Block()),
    ("(unclosed G1 X1", Block()),
    ("g1 x1 f100", block("G1X1F100", ("G1",), ("X", 1.0), ("F", 100.0))),
    ("G1 X1 (move) Y2", block("G1X1Y2", ("G1",), ("X", 1.0), ("Y", 2.0))),
    ("G1 X1 ; Y2 (Z3)", block("G1X1", ("G1",), ("X", 1.0))),
    ("G1 X1 ((nested) Y2", block("G1X1Y2", ("G1",), ("X", 1.0), ("Y", 2.0))),
    ("/G1 X1", block("G1X1", ("G1",), ("X", 1.0))),  # block delete: '/' ignored
    ("G1\tX1\x00\x7f", Error(1)),  # tab and NUL dropped, DEL kept and not a letter
    ("G1\tX1\x01", block("G1X1", ("G1",), ("X", 1.0))),
    ("G1 X1?", block("G1X1", ("G1",), ("X", 1.0))),  # real-time bytes never reach the line
    ("G1 (what?) X~1!", block("G1X1", ("G1",), ("X", 1.0))),
    (b"G1 X\x851\xff\n", block("G1X1", ("G1",), ("X", 1.0))),
    ("G1 Xé1", block("G1X1", ("G1",), ("X", 1.0))),
    ("G1 X1 G1 X2", Error(24)),
    ("G1X" + "1" * 76, block("G1X" + "1" * 76, ("G1",), ("X", 11111111e68))),
    ("G1X" + "1" * 77, Error(11)),
    (
        "G1 X1 Y2 Z3 " + " " * 100 + "F100",
        block("G1X1Y2Z3F100", ("G1",), ("X", 1.0), ("Y", 2.0), ("Z", 3.0), ("F", 100.0)),
    ),
    ("G1 X1 (" + "c" * 200 + ")", block("G1X1", ("G1",), ("X", 1.0))),
]


@pytest.mark.parametrize(("line", "expected"), LINE_BUFFER)
def test_line_buffer(line: str | bytes, expected: object) -> None:
    assert parse_line(line) == expected


def test_more_than_one_line_is_refused() -> None:
    for text in ("G1\nX1", "G1\rX1", "G1\n\n", "G1\n\r"):
        with pytest.raises(ValueError, match="text: one line expected"):
            parse_line(text)


WORDS = [
    ("1", Error(1)),
    ("=1", Error(1)),
    ("%", Error(1)),
    ("G1 X1.2.3", Error(1)),
    ("G", Error(2)),
    ("X", Error(2)),
    ("X-", Error(2)),
    ("X.", Error(2)),
    ("X--1", Error(2)),
    ("G1 X1e3", Error(20)),  # X1 then an E word
    ("G1 X1e", Error(2)),  # E without a number
    ("G1 X1E-3", Error(20)),
    ("G1 Q5", Error(20)),
    ("A1", Error(20)),
    ("G5", Error(20)),
    ("G38", Error(20)),
    ("G28.2", Error(20)),
    ("G90.1", Error(20)),
    ("G61.1", Error(20)),
    ("G43", Error(20)),
    ("G43.2", Error(20)),
    ("M6", Error(20)),
    ("M7", Error(20)),  # mist coolant is a compile option, off by default
    ("M56", Error(20)),
    ("G256", Error(20)),
    ("G-1", Error(20)),
    ("G1.5", Error(23)),
    ("G17.1", Error(23)),
    ("G4.5", Error(23)),
    ("G10.5", Error(23)),
    ("M3.5", Error(23)),
    ("G0 G1", Error(24)),  # both use axis words: found before the modal group
    ("G80 G0", Error(21)),
    ("G90 G91", Error(21)),
    ("G17 G18", Error(21)),
    ("G20 G21", Error(21)),
    ("M3 M5", Error(21)),
    ("M2 M30", Error(21)),
    ("G4 G53", Error(21)),
    ("G1 G92 X1", Error(24)),
    ("G1 G1.5", Error(24)),  # the axis-command conflict is found before the decimals
    ("G1 G38", Error(24)),
    ("G0 G43.1 Z1", Error(24)),
    ("G28 G30", Error(24)),
    ("G1 X1 X2", Error(25)),
    ("F1 F2", Error(25)),
    ("F-1", Error(4)),
    ("S-1", Error(4)),
    ("P-1", Error(4)),
    ("N-1", Error(4)),
    ("T-1", Error(4)),
    ("T256", Error(38)),
    ("T1 T256", Error(38)),  # 38 before the repeat
    ("G0 X-1 Y-2 Z-3", block("G0X-1Y-2Z-3", ("G0",), ("X", -1.0), ("Y", -2.0), ("Z", -3.0))),
    ("G00 G01", Error(24)),
    ("G01 X1", block("G01X1", ("G1",), ("X", 1.0))),
    ("G0.001", block("G0.001", ("G0",))),  # Grbl checks decimals to hundredths only
    ("M03 S1000", block("M03S1000", ("M3",), ("S", 1000.0))),
    ("G38.2 Z-5 F10", block("G38.2Z-5F10", ("G38.2",), ("Z", -5.0), ("F", 10.0))),
    ("G28.1", block("G28.1", ("G28.1",))),
    ("G92.1", block("G92.1", ("G92.1",))),
    ("G91.1", block("G91.1", ("G91.1",))),
    ("G49.3", block("G49.3", ("G49",))),  # G49's decimals are ignored
    ("G43.1 Z1", block("G43.1Z1", ("G43.1",), ("Z", 1.0))),
    ("G1 G4 P1", block("G1G4P1", ("G1", "G4"), ("P", 1.0))),
    ("T255", block("T255", (), ("T", 255.0))),
    (
        "N10 G17 G21 G40 G49 G54 G61 G80 G90 G94 M5 M9",
        block(
            "N10G17G21G40G49G54G61G80G90G94M5M9",
            ("G17", "G21", "G40", "G49", "G54", "G61", "G80", "G90", "G94", "M5", "M9"),
            ("N", 10.0),
        ),
    ),
]


@pytest.mark.parametrize(("line", "expected"), WORDS)
def test_words(line: str, expected: object) -> None:
    assert parse_line(line) == expected


def test_block_accessors() -> None:
    parsed = parse_line("G1 G91 X1.5 F600 M3")
    assert isinstance(parsed, Block)
    assert parsed.get("X") == 1.5
    assert parsed.get("Y") is None
    assert parsed.get("Y", 0.0) == 0.0
    assert parsed.command("motion") == "G1"
    assert parsed.command("distance") == "G91"
    assert parsed.command("spindle") == "M3"
    assert parsed.command("units") is None
    assert not parsed.is_empty
    assert Block().is_empty


@pytest.mark.parametrize("state", [State.ALARM, State.JOG])
def test_gcode_locked_in_alarm_and_jog(state: State) -> None:
    assert parse_line("G1 X1 F100", state) == Error(9)
    assert parse_line("G5", state) == Error(9)  # the lock comes before parsing
    assert parse_line("", state) == Block()  # an empty line is always ok
    assert parse_line("(comment)", state) == Block()


@pytest.mark.parametrize("state", [State.RUN, State.HOLD, State.CHECK, State.DOOR])
def test_gcode_accepted_while_moving(state: State) -> None:
    assert isinstance(parse_line("G1 X1 F100", state), Block)


IDLE, RUN, HOLD, JOG, ALARM, CHECK = (
    State.IDLE,
    State.RUN,
    State.HOLD,
    State.JOG,
    State.ALARM,
    State.CHECK,
)

SYSTEM = [
    ("$", IDLE, Help()),
    ("$", RUN, Help()),
    ("$$", IDLE, ViewSettings()),
    ("$$", ALARM, ViewSettings()),
    ("$$", JOG, ViewSettings()),
    ("$$", RUN, Error(8)),
    ("$$", HOLD, Error(8)),
    ("$$$", IDLE, Error(3)),
    ("$G", RUN, ViewParserState()),
    ("$g", IDLE, ViewParserState()),
    ("$GX", IDLE, Error(3)),
    ("$C", IDLE, ToggleCheckMode()),
    ("$C", CHECK, ToggleCheckMode()),
    ("$C", ALARM, Error(8)),
    ("$C", RUN, Error(8)),
    ("$X", ALARM, Unlock()),
    ("$X", IDLE, Unlock()),
    ("$x", RUN, Unlock()),
    ("$XY", ALARM, Error(3)),
    ("$#", IDLE, ViewParameters()),
    ("$#", ALARM, ViewParameters()),
    ("$#", RUN, Error(8)),
    ("$#1", IDLE, Error(3)),
    ("$H", IDLE, Home()),
    ("$H", ALARM, Home()),
    ("$H", RUN, Error(8)),
    ("$HX", IDLE, Home("X")),
    ("$SLP", IDLE, Sleep()),
    ("$slp", ALARM, Sleep()),
    ("$SL", IDLE, Error(3)),
    ("$SLPX", IDLE, Error(3)),
    ("$S", IDLE, Error(3)),
    ("$SLP", JOG, Error(8)),
    ("$I", IDLE, ViewBuildInfo()),
    ("$I=my plotter", IDLE, SetBuildInfo("MYPLOTTER")),
    ("$IX", IDLE, Error(3)),
    ("$RST=$", IDLE, Restore("$")),
    ("$RST=#", ALARM, Restore("#")),
    ("$RST=*", IDLE, Restore("*")),
    ("$RST=", IDLE, Error(3)),
    ("$RST=X", IDLE, Error(3)),
    ("$RST", IDLE, Error(3)),
    ("$RST=$$", IDLE, Error(3)),
    ("$RST=*", RUN, Error(8)),
    ("$N", IDLE, ViewStartupLines()),
    ("$N", ALARM, ViewStartupLines()),
    ("$N", RUN, Error(8)),
    ("$N0=G21 G90", IDLE, SetStartupLine(0, Block("G21G90", ("G21", "G90")))),
    ("$N1=", IDLE, SetStartupLine(1, Block())),
    ("$N0=G21", ALARM, Error(8)),
    ("$N0G21", IDLE, Error(3)),
    ("$NX=G21", IDLE, Error(2)),
    ("$N0=G5", IDLE, Error(20)),
    ("$100=80", IDLE, SetSetting(100, 80.0)),
    ("$100=80", ALARM, SetSetting(100, 80.0)),
    ("$100=80", RUN, Error(8)),
    ("$10=3", IDLE, SetSetting(10, 3.0)),
    ("$11=0.010", IDLE, SetSetting(11, 0.01)),
    ("$132 = 200.5", IDLE, SetSetting(132, 200.5)),
    ("$0=3", IDLE, SetSetting(0, 3.0)),
    ("$0=2.9", IDLE, Error(6)),
    ("$100=-1", IDLE, Error(4)),
    ("$7=-1", IDLE, Error(4)),  # the negative value is found before the unknown setting
    ("$7=1", IDLE, Error(3)),
    ("$103=1", IDLE, Error(3)),
    ("$140=1", IDLE, Error(3)),
    ("$256=1", IDLE, Error(3)),
    ("$1=", IDLE, Error(2)),
    ("$1", IDLE, Error(3)),
    ("$=1", IDLE, Error(2)),
    ("$Z", IDLE, Error(2)),
    ("$1=2X", IDLE, Error(3)),
    ("$1=2=", IDLE, Error(3)),
    ("$1=1e3", IDLE, Error(3)),
    ("$J=G91 X1 F100", IDLE, block("$J=G91X1F100", ("G91",), ("X", 1.0), ("F", 100.0))),
    ("$J=X1F100", JOG, block("$J=X1F100", (), ("X", 1.0), ("F", 100.0))),
    ("$J=X1F100", RUN, Error(8)),
    ("$J=X1F100", ALARM, Error(8)),
    ("$J", IDLE, Error(3)),
    ("$JG91X1", IDLE, Error(3)),
    ("$J=G91 X1e3 F100", IDLE, Error(20)),
    ("$J=", IDLE, block("$J=")),
]


@pytest.mark.parametrize(("line", "state", "expected"), SYSTEM)
def test_system_commands(line: str, state: State, expected: object) -> None:
    assert parse_line(line, state) == expected


def step(lines: list[str], state: ParserState | None = None) -> Step | Error:
    """Run ``lines`` through the parser state; return the last line's outcome."""
    state = state or ParserState()
    outcome: Step | Error = Step(state)
    for line in lines:
        parsed = parse_line(line)
        assert isinstance(parsed, Block), (line, parsed)
        outcome = state.step(parsed)
        if isinstance(outcome, Step):
            state = outcome.state
    return outcome


STEPS = [
    (["G1 X1"], Error(22)),
    (["G1"], Error(22)),  # G1 needs a feed rate even without axis words
    (["G0 X1"], Step(ParserState(position=(1.0, 0.0, 0.0)), (1.0, 0.0, 0.0), rapid=True)),
    (["X1"], Step(ParserState(position=(1.0, 0.0, 0.0)), (1.0, 0.0, 0.0), rapid=True)),
    (["G1 F600"], Step(ParserState(motion="G1", feed_rate=600.0), feed_rate=600.0)),
    (
        ["G1 X1 Y-2 Z0.5 F600"],
        Step(
            ParserState(motion="G1", feed_rate=600.0, position=(1.0, -2.0, 0.5)),
            (1.0, -2.0, 0.5),
            feed_rate=600.0,
        ),
    ),
    (["G1 X1 F600", "G1 Y1"], (1.0, 1.0, 0.0)),
    (["G91 G1 X1 F600", "X1", "Y-3"], (2.0, -3.0, 0.0)),
    (["G20 G1 X1 F10"], Step),
    (["G1 X1 F0"], Error(22)),
    (["G93", "G1 X1"], Error(22)),
    (["G93 G1 X1 F6000", "G1 X2"], Error(22)),  # inverse time forgets F after each block
    (["G93", "G0 X5"], (5.0, 0.0, 0.0)),
    (["G1 F600", "G93 G1 X1 F6000", "G94", "G1 X2"], Error(22)),  # undefined after G93
    (["G1 F600", "G94 G1 X2"], (2.0, 0.0, 0.0)),
    (["G4"], Error(28)),
    (["G4 P0.5"], Step(ParserState(), dwell=0.5)),
    (["G4 P1 X2"], (2.0, 0.0, 0.0)),  # axis words beside G4 move in the current mode
    (["G80"], Step(ParserState(motion="G80"))),
    (["G80", "X1"], Error(31)),
    (["G80 X1"], Error(31)),
    (["G53 G0 X5"], (5.0, 0.0, 0.0)),
    (["G91 G0 X1", "G53 X5"], (5.0, 0.0, 0.0)),  # G53 ignores G91
    (["G80", "G53 X1"], Error(30)),
    (["G1 X1 F100 I5"], Error(36)),
    (["G0 R1"], Error(36)),
    (["L2"], Error(36)),
    (["G4 P1 F100 S5 T1 N10"], Step),
    (["N10000001"], Error(27)),
    (["N10000000"], Step),
    (["G2 X1 Y1 I1 F100"], Error(20)),  # Grbl accepts arcs; this model does not
    (["G38.2 Z-5 F10"], Error(20)),
    (["G92 X0"], Error(20)),
    (["G55"], Error(20)),
    (["G54 G17 G40 G49 G61 G91.1 M9 M1"], Step),
    (["$J=X1"], Error(22)),
    (["$J=X1F0"], Error(22)),
    (["$J=G1X1F100"], Error(16)),
    (["$J=G0X1F100"], Error(16)),
    (["$J=G93X1F100"], Error(16)),
    (["$J=M3X1F100"], Error(16)),
    (["$J=G4P1X1F100"], Error(16)),
    (["$J=X1F100S5"], Error(36)),
    (["$J=X1F100T1"], Error(36)),
    (["$J=N5X1F100"], Step),
    (["$J=G20G91X1F10"], Step),
    (["$J=G53X1F100"], Step),
]


@pytest.mark.parametrize(("lines", "expected"), STEPS)
def test_steps(lines: list[str], expected: object) -> None:
    outcome = step(lines)
    if expected is Step:
        assert isinstance(outcome, Step)
    elif isinstance(expected, tuple):
        assert isinstance(outcome, Step)
        assert outcome.target == expected
        assert outcome.state.position == expected
    else:
        assert outcome == expected


def test_inches() -> None:
    outcome = step(["G20 G1 X1 Y-0.5 F10"])
    assert outcome.target == pytest.approx((25.4, -12.7, 0.0))
    assert outcome.feed_rate == pytest.approx(254.0)
    assert outcome.state.units == "G20"
    assert step(["G20", "G93 G1 X1 F10"]).feed_rate == 10.0  # inverse time is not converted


def test_jog_leaves_modal_state_but_moves_position() -> None:
    start = ParserState(motion="G1", feed_rate=600.0, position=(1.0, 2.0, 0.0))
    outcome = step(["$J=G20 G91 X1 F10"], start)
    assert outcome.jog
    assert outcome.target == pytest.approx((26.4, 2.0, 0.0))
    assert outcome.feed_rate == pytest.approx(254.0)
    assert outcome.state == ParserState(
        motion="G1", feed_rate=600.0, position=outcome.target
    )  # G20 and G91 applied to the jog only
    assert step(["$J=G53 X5 F100"], start).target == (5.0, 2.0, 0.0)


def test_jog_without_axes_goes_to_origin() -> None:
    """Grbl 1.1h's jog target starts at zero and only given axes are filled in."""
    outcome = step(["$J=F100"], ParserState(position=(3.0, 4.0, 5.0)))
    assert outcome.target == (0.0, 0.0, 0.0)


def test_spindle_tool_and_program_flow() -> None:
    outcome = step(["M3 S1000"])
    assert (outcome.state.spindle, outcome.state.spindle_speed) == ("M3", 1000.0)
    assert outcome.target is None
    outcome = step(["M3 S1000", "S500", "M5"])
    assert (outcome.state.spindle, outcome.state.spindle_speed) == ("M5", 500.0)
    assert step(["T5"]).state.tool == 5
    assert step(["T5", "G0 X1"]).state.tool == 0  # Grbl forgets T on blocks without it
    assert step(["M0"]).program_flow == "M0"
    assert step(["M1"]).program_flow is None  # optional stop is ignored
    end = step(["G91 G93 G1 X1 F100 M3 S300 M8 G18", "M30"])
    assert end.program_flow == "M30"
    assert end.state == ParserState(
        motion="G1", units="G21", spindle_speed=300.0, position=(1.0, 0.0, 0.0)
    )  # M2/M30 reset motion, plane, distance, feed mode, spindle and coolant
    assert step(["M2"]).program_flow == "M2"


def test_parser_state_report() -> None:
    assert ParserState().report() == "G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0"
    state = step(["G1 G91 F600.4 M3 S1000 M8 T2"]).state
    assert state.report() == "G1 G54 G17 G21 G91 G94 M3 M8 T2 F600 S1000"
    assert state.report(inches=True) == "G1 G54 G17 G21 G91 G94 M3 M8 T2 F23.6 S1000"


@given(st.text(max_size=120))
def test_any_text_line_gives_an_answer(text: str) -> None:
    text = text.replace("\r", "").replace("\n", "")
    for state in State:
        parsed = parse_line(text, state)
        assert parsed is not None
        if isinstance(parsed, Block):
            assert isinstance(ParserState().step(parsed), Step | Error)


@given(st.binary(max_size=120))
def test_any_bytes_line_gives_an_answer(data: bytes) -> None:
    data = data.replace(b"\r", b"").replace(b"\n", b"")
    parsed = parse_line(data)
    if isinstance(parsed, Block):
        assert parsed.text.isascii() and len(parsed.text) <= 79
        assert isinstance(ParserState().step(parsed), Step | Error)
