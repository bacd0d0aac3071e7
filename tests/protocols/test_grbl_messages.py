"""What Grbl 1.1 sends: golden lines, exact bytes, round trips and the incremental decoder.

Golden vectors are lines copied from serial transcripts of the Grbl 1.1h firmware
(``grblsim_1.1h_*.log``); the bytes around them (``\\r\\n`` line ends, the empty line before the
welcome) follow the firmware's report.c.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocols.grbl import (
    SETTINGS,
    Alarm,
    Error,
    Feedback,
    Garbage,
    Msg,
    Ok,
    ResponseDecoder,
    Setting,
    StartupLine,
    StartupResult,
    State,
    Status,
    Welcome,
    format_float,
    format_message,
    parse_message,
)
from firmware_protocols.grbl.codes import INTEGER_SETTINGS

PINS = "PXYZRHS"

GOLDEN = [
    ("ok", Ok()),
    ("error:22", Error(22)),
    ("error:9", Error(9)),
    ("ALARM:3", Alarm(3)),
    ("Grbl 1.1h ['$' for help]", Welcome("1.1h")),
    ("[MSG:'$H'|'$X' to unlock]", Msg("'$H'|'$X' to unlock")),
    ("[MSG:Caution: Unlocked]", Msg("Caution: Unlocked")),
    (
        "<Idle|MPos:0.000,0.000,0.000|FS:0,0|Pn:PXYZRHS|WCO:0.000,0.000,0.000>",
        Status(
            State.IDLE,
            mpos=(0.0, 0.0, 0.0),
            feed=0.0,
            spindle=0.0,
            pins=PINS,
            wco=(0.0, 0.0, 0.0),
        ),
    ),
    (
        "<Run|MPos:23.764,0.000,0.000|FS:54,0|Pn:PXYZRHS|Ov:100,100,100>",
        Status(
            State.RUN,
            mpos=(23.764, 0.0, 0.0),
            feed=54.0,
            spindle=0.0,
            pins=PINS,
            overrides=(100, 100, 100),
        ),
    ),
    (
        "<Hold:0|MPos:7.748,0.000,0.000|FS:0,0|Pn:PXYZRHS>",
        Status(State.HOLD, 0, mpos=(7.748, 0.0, 0.0), feed=0.0, spindle=0.0, pins=PINS),
    ),
    (
        "<Alarm|MPos:23.764,0.000,0.000|FS:0,0|Pn:PXYZRHS|WCO:0.000,0.000,0.000>",
        Status(
            State.ALARM,
            mpos=(23.764, 0.0, 0.0),
            feed=0.0,
            spindle=0.0,
            pins=PINS,
            wco=(0.0, 0.0, 0.0),
        ),
    ),
    (
        "<Run|MPos:-19.950,-1.363,0.000|Bf:0,28|FS:5730,0|Pn:PXYZRHS>",
        Status(
            State.RUN,
            mpos=(-19.95, -1.363, 0.0),
            buffer=(0, 28),
            feed=5730.0,
            spindle=0.0,
            pins=PINS,
        ),
    ),
    (
        "<Idle|MPos:50.000,0.000,0.000|Bf:15,128|FS:0,0|Pn:PXYZRHS|WCO:0.000,0.000,0.000>",
        Status(
            State.IDLE,
            mpos=(50.0, 0.0, 0.0),
            buffer=(15, 128),
            feed=0.0,
            spindle=0.0,
            pins=PINS,
            wco=(0.0, 0.0, 0.0),
        ),
    ),
    (
        "<Run|MPos:50.000,0.000,0.000|Bf:14,128|FS:3000,0|Pn:PXYZRHS|Ov:100,100,100>",
        Status(
            State.RUN,
            mpos=(50.0, 0.0, 0.0),
            buffer=(14, 128),
            feed=3000.0,
            spindle=0.0,
            pins=PINS,
            overrides=(100, 100, 100),
        ),
    ),
]


@pytest.mark.parametrize(("line", "message"), GOLDEN)
def test_golden_lines_parse(line: str, message: object) -> None:
    assert parse_message(line) == message


@pytest.mark.parametrize(("line", "message"), GOLDEN)
def test_golden_lines_format_exactly(line: str, message: object) -> None:
    expected = line + "\r\n"
    if isinstance(message, Welcome):
        expected = "\r\n" + expected
    assert format_message(message) == expected.encode("ascii")


def test_status_fields() -> None:
    status = parse_message("<Run|MPos:40.475,0.000,0.000|Bf:1,128|FS:3750,0|Pn:PXYZRHS>")
    assert status.state is State.RUN
    assert status.substate is None
    assert status.mpos == (40.475, 0.0, 0.0)
    assert status.wpos is None
    assert status.buffer == (1, 128)
    assert (status.feed, status.spindle) == (3750.0, 0.0)
    assert status.pins == "PXYZRHS"
    assert status.wco is None and status.overrides is None and status.accessories is None


OTHER_LINES = [
    (
        "<Door:2|WPos:-2.500,0.000,11.000|F:500>",
        Status(State.DOOR, 2, wpos=(-2.5, 0.0, 11.0), feed=500.0),
    ),
    (
        "<Jog|MPos:1.000,2.000,3.000|Ln:99999|FS:500,8000|Ov:120,50,100|A:SF>",
        Status(
            State.JOG,
            mpos=(1.0, 2.0, 3.0),
            line=99999,
            feed=500.0,
            spindle=8000.0,
            overrides=(120, 50, 100),
            accessories="SF",
        ),
    ),
    (
        "<Check|MPos:0.000,0.000,0.000|FS:0,0|New:1,2>",
        Status(State.CHECK, mpos=(0.0, 0.0, 0.0), feed=0.0, spindle=0.0, extra=(("New", "1,2"),)),
    ),
    ("<Sleep|MPos:0.0000,0.0000,0.0000>", Status(State.SLEEP, mpos=(0.0, 0.0, 0.0))),
    (
        "[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]",
        Feedback("GC", "G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0"),
    ),
    (
        "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]",
        Feedback("HLP", "$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x"),
    ),
    ("[VER:1.1h.20190830:]", Feedback("VER", "1.1h.20190830:")),
    ("[OPT:V,15,128]", Feedback("OPT", "V,15,128")),
    ("[G54:0.000,0.000,0.000]", Feedback("G54", "0.000,0.000,0.000")),
    ("[PRB:0.000,0.000,0.000:0]", Feedback("PRB", "0.000,0.000,0.000:0")),
    ("[echo:G1X0.540Y10.4F100]", Feedback("echo", "G1X0.540Y10.4F100")),
    ("$11=0.010", Setting(11, 0.01)),
    ("$10=3", Setting(10, 3.0)),
    ("$130=200.000", Setting(130, 200.0)),
    ("$30=1000", Setting(30, 1000.0)),
    ("$N0=G21G90", StartupLine(0, "G21G90")),
    ("$N1=", StartupLine(1, "")),
    (">G54G20:ok", StartupResult("G54G20", Ok())),
    (">G1X1:error:22", StartupResult("G1X1", Error(22))),
    (">:error:7", StartupResult("", Error(7))),
    ("GrblHAL 1.1f ['$' or '$HELP' for help]", None),
    ("Grbl 1.1f ['$' for help]", Welcome("1.1f")),
    ("OK", None),
    ("ok ", None),
    ("error:", None),
    ("error:x", None),
    ("ALARM:", None),
    ("<Idle", None),
    ("<Busy|MPos:0.000,0.000,0.000>", None),
    ("<Idle|MPos:0.000,zero,0.000>", None),
    ("<Idle|MPos:0.000,0.000,0.000|Bf:15>", None),
    ("<Idle|MPos:0.000,0.000,0.000|Ov:100,100>", None),
    ("<Idle|MPos:0.000,0.000,0.000|Pn:>", None),
    ("<Idle|MPos>", None),
    ("<Hold:x|MPos:0.000,0.000,0.000>", None),
    ("[no colon]", None),
    ("$x=1", None),
    ("", None),
]


@pytest.mark.parametrize(("line", "message"), OTHER_LINES)
def test_other_lines(line: str, message: object) -> None:
    assert parse_message(line) == message


def test_descriptions() -> None:
    assert Error(22).description == "undefined feed rate"
    assert Error(99).description == "unknown error"
    assert Alarm(3).description == "reset while in motion, position likely lost"
    assert Alarm(0).description == "unknown alarm"


@pytest.mark.parametrize(
    ("value", "decimals", "expected"),
    [
        (0.0, 3, "0.000"),
        (-0.0, 3, "0.000"),
        (-0.0001, 3, "-0.000"),  # Grbl prints the sign of any negative value
        (23.764, 3, "23.764"),
        (-19.95, 3, "-19.950"),
        (0.5, 3, "0.500"),
        (0.0005, 3, "0.001"),
        (54.4, 0, "54"),
        (54.5, 0, "55"),  # half up
        (23.63779, 1, "23.6"),
        (1.0, 4, "1.0000"),
    ],
)
def test_format_float(value: float, decimals: int, expected: str) -> None:
    assert format_float(value, decimals) == expected


def test_format_inches_and_special_messages() -> None:
    status = Status(State.RUN, mpos=(1.0, -0.03937, 0.0), feed=23.6, spindle=0.0, wco=(0, 0, 0))
    assert format_message(status, inches=True) == (
        b"<Run|MPos:1.0000,-0.0394,0.0000|FS:23.6,0|WCO:0.0000,0.0000,0.0000>\r\n"
    )
    assert format_message(Setting(11, 0.01)) == b"$11=0.010\r\n"
    assert format_message(Setting(10, 3)) == b"$10=3\r\n"
    assert format_message(Setting(31, 0)) == b"$31=0\r\n"
    assert format_message(StartupResult("G21", Error(7))) == b">G21:error:7\r\n"
    assert format_message(Garbage(b"\xff\x00")) == b"\xff\x00"
    with pytest.raises(TypeError, match="message: not a Grbl message"):
        format_message("ok")  # type: ignore[arg-type]


# --- the incremental decoder --------------------------------------------------------------------

# grblsim_1.1h_reset.log, raw transcript, as the bytes Grbl sends.
RESET_STREAM = (
    b"ok\r\n"
    b"ok\r\n"
    b"<Run|MPos:23.764,0.000,0.000|FS:300,0|Pn:PXYZRHS|Ov:100,100,100>\r\n"
    b"ALARM:3\r\n"
    b"\r\nGrbl 1.1h ['$' for help]\r\n"
    b"[MSG:'$H'|'$X' to unlock]\r\n"
    b"<Alarm|MPos:23.764,0.000,0.000|FS:0,0|Pn:PXYZRHS|WCO:0.000,0.000,0.000>\r\n"
    b"error:9\r\n"
    b"[MSG:Caution: Unlocked]\r\n"
    b"ok\r\n"
    b"<Idle|MPos:23.764,0.000,0.000|FS:0,0|Pn:PXYZRHS|Ov:100,100,100>\r\n"
)
RESET_MESSAGES = [
    Ok(),
    Ok(),
    Status(
        State.RUN,
        mpos=(23.764, 0.0, 0.0),
        feed=300.0,
        spindle=0.0,
        pins=PINS,
        overrides=(100, 100, 100),
    ),
    Alarm(3),
    Welcome("1.1h"),
    Msg("'$H'|'$X' to unlock"),
    Status(
        State.ALARM,
        mpos=(23.764, 0.0, 0.0),
        feed=0.0,
        spindle=0.0,
        pins=PINS,
        wco=(0.0, 0.0, 0.0),
    ),
    Error(9),
    Msg("Caution: Unlocked"),
    Ok(),
    Status(
        State.IDLE,
        mpos=(23.764, 0.0, 0.0),
        feed=0.0,
        spindle=0.0,
        pins=PINS,
        overrides=(100, 100, 100),
    ),
]


def feed_chunks(chunks: list[bytes], decoder: ResponseDecoder | None = None) -> list[object]:
    decoder = decoder or ResponseDecoder()
    return [message for chunk in chunks for message in decoder.feed(chunk)]


def test_decoder_whole() -> None:
    decoder = ResponseDecoder()
    assert decoder.feed(RESET_STREAM) == RESET_MESSAGES
    assert decoder.pending == b""


def test_decoder_matches_formatter() -> None:
    assert b"".join(format_message(m) for m in RESET_MESSAGES) == RESET_STREAM


def test_decoder_halves_at_every_split() -> None:
    for cut in range(len(RESET_STREAM) + 1):
        chunks = [RESET_STREAM[:cut], RESET_STREAM[cut:]]
        assert feed_chunks(chunks) == RESET_MESSAGES, cut


def test_decoder_byte_by_byte() -> None:
    decoder = ResponseDecoder()
    received = []
    for i in range(len(RESET_STREAM)):
        received += decoder.feed(RESET_STREAM[i : i + 1])
        assert len(decoder.pending) <= 80
    assert received == RESET_MESSAGES


def test_decoder_keeps_partial_line() -> None:
    decoder = ResponseDecoder()
    assert decoder.feed(b"ok\r\nerr") == [Ok()]
    assert decoder.pending == b"err"
    assert decoder.feed(b"or:2") == []
    assert decoder.feed(b"0\r") == [Error(20)]
    assert decoder.feed(b"\n") == []  # the \n of a \r\n split across reads
    decoder.feed(b"<Idle|MPos:0.0")
    decoder.reset()
    assert decoder.pending == b""
    assert decoder.feed(b"ok\n") == [Ok()]


@pytest.mark.parametrize("ending", [b"\n", b"\r\n", b"\r", b"\n\r", b"\r\n\r\n"])
def test_decoder_line_endings(ending: bytes) -> None:
    stream = ending.join([b"ok", b"error:22", b"ALARM:3"]) + ending
    assert ResponseDecoder().feed(stream) == [Ok(), Error(22), Alarm(3)]


def test_decoder_after_garbage() -> None:
    decoder = ResponseDecoder()
    assert decoder.feed(b"\x00\xff\xfeok\r\n") == [Garbage(b"\x00\xff\xfe"), Ok()]
    assert decoder.feed(b"\xf0\x9f\x98Grbl 1.1h ['$' for help]\r\n") == [
        Garbage(b"\xf0\x9f\x98"),
        Welcome("1.1h"),
    ]
    assert decoder.feed(b"noise\r\nok\r\n") == [Garbage(b"noise"), Ok()]
    assert decoder.feed(b"ok\x00junk\r\nok\r\n") == [Garbage(b"ok\x00junk"), Ok()]
    assert decoder.feed(b"<Idle|MPos:1,2\x07\r\n") == [Garbage(b"<Idle|MPos:1,2\x07")]
    assert decoder.feed(RESET_STREAM) == RESET_MESSAGES


def test_decoder_long_garbage_is_bounded() -> None:
    decoder = ResponseDecoder(max_line=100)
    assert decoder.feed(b"x" * 100) == []
    assert decoder.feed(b"x") == [Garbage(b"x" * 101)]
    assert decoder.pending == b""
    assert decoder.feed(b"yy\r\nok\r\n") == [Garbage(b"yy"), Ok()]
    assert decoder.feed(b"z" * 1000 + b"\nok\n") == [Garbage(b"z" * 1000), Ok()]


def test_decoder_rejects_bad_max_line() -> None:
    for value in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="max_line: must be a positive integer"):
            ResponseDecoder(max_line=value)  # type: ignore[arg-type]


# --- properties ---------------------------------------------------------------------------------

printable = st.text(alphabet=st.characters(min_codepoint=0x20, max_codepoint=0x7E), max_size=40)
millis = st.integers(min_value=-(10**7), max_value=10**7).map(lambda i: i / 1000)
axes = st.tuples(millis, millis, millis)
states = st.sampled_from(list(State))


@st.composite
def statuses(draw) -> Status:
    state = draw(states)
    substate = draw(st.integers(0, 3)) if state in (State.HOLD, State.DOOR) else None
    position = draw(axes)
    machine = draw(st.booleans())
    feed = float(draw(st.integers(0, 100_000)))
    spindle = draw(st.none() | st.integers(0, 30_000).map(float))
    optional = st.none
    return Status(
        state,
        substate,
        mpos=position if machine else None,
        wpos=None if machine else position,
        buffer=draw(optional() | st.tuples(st.integers(0, 15), st.integers(0, 128))),
        line=draw(optional() | st.integers(0, 10**7)),
        feed=feed,
        spindle=spindle,
        pins=draw(optional() | st.text(alphabet="XYZPDHRS", min_size=1, max_size=8)),
        wco=draw(optional() | axes),
        overrides=draw(optional() | st.tuples(*[st.integers(10, 200)] * 3)),
        accessories=draw(optional() | st.text(alphabet="SCFM", min_size=1, max_size=3)),
        extra=tuple(
            draw(
                st.lists(
                    st.tuples(
                        st.from_regex(r"[a-z][a-z0-9]{0,5}", fullmatch=True),
                        st.from_regex(r"[0-9A-Z,.]{0,8}", fullmatch=True),
                    ),
                    max_size=2,
                )
            )
        ),
    )


def setting_values(number: int) -> st.SearchStrategy[Setting]:
    if number in INTEGER_SETTINGS or number in (30, 31):
        return st.integers(0, 255).map(lambda v: Setting(number, float(v)))
    return st.integers(0, 10**7).map(lambda v: Setting(number, v / 1000))


messages = st.one_of(
    st.just(Ok()),
    st.integers(0, 255).map(Error),
    st.integers(0, 255).map(Alarm),
    st.builds(Welcome, st.from_regex(r"[0-9a-z.]{1,8}", fullmatch=True), printable),
    statuses(),
    printable.map(Msg),
    st.builds(
        Feedback,
        st.from_regex(r"[A-Za-z][A-Za-z0-9]{0,4}", fullmatch=True).filter(lambda k: k != "MSG"),
        printable,
    ),
    st.sampled_from(sorted(SETTINGS)).flatmap(setting_values),
    st.builds(StartupLine, st.integers(0, 9), printable),
    st.builds(
        StartupResult,
        printable,
        st.just(Ok()) | st.integers(0, 255).map(Error),
    ),
)


@given(messages)
def test_round_trip(message: object) -> None:
    assert ResponseDecoder().feed(format_message(message)) == [message]


@given(st.lists(messages, max_size=8), st.data())
def test_round_trip_stream_in_any_chunks(sent: list[object], data: st.DataObject) -> None:
    stream = b"".join(format_message(m) for m in sent)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    chunks = [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]
    assert feed_chunks(chunks) == sent


@given(st.binary(max_size=300), st.lists(st.integers(0, 300), max_size=8))
def test_any_bytes_never_raise(data: bytes, cuts: list[int]) -> None:
    cuts = sorted(c for c in cuts if c <= len(data))
    chunks = [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True)]
    decoder = ResponseDecoder(max_line=1000)
    received = feed_chunks(chunks, decoder)
    assert received == ResponseDecoder(max_line=1000).feed(data)  # chunking does not matter
    garbage = b"".join(m.data for m in received if isinstance(m, Garbage))
    assert len(garbage) + len(decoder.pending) <= len(data)
    # and it resynchronises: whatever came before, a fresh line is read
    assert decoder.feed(b"\nok\r\n")[-1] == Ok()


@given(st.binary(max_size=200))
def test_garbage_then_messages(noise: bytes) -> None:
    received = ResponseDecoder().feed(noise + b"\r\n" + RESET_STREAM)
    assert received[len(received) - len(RESET_MESSAGES) :] == RESET_MESSAGES
