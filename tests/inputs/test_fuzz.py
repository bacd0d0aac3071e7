"""Fuzzing: any bytes give traces or an InputError, never another exception or a hang.

Each example must finish within the deadline (inputs are a few kB: milliseconds of work), so a
hang or a blow-up fails the test rather than stalling the suite.
"""

from __future__ import annotations

import json
from datetime import timedelta

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tagbot.errors import InputError
from tagbot.inputs import (
    Trace,
    read_gml,
    read_points_csv,
    read_points_json,
    read_svg,
    read_traces_bytes,
)
from tagbot.inputs.gml import read_gml_json
from tagbot.inputs.points import read_points_json_object

from .conftest import DATA

FUZZ = settings(
    max_examples=150,
    deadline=timedelta(seconds=2),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

READERS = [read_traces_bytes, read_gml, read_points_csv, read_points_json, read_svg]

SEEDS = [
    (DATA / name).read_bytes()
    for name in (
        "spec10.gml",
        "legacy.gml",
        "sideways.gml",
        "restart.gml",
        "epoch_ms.gml",
        "truncated.gml",
        "book.json",
        "book_xml_string.jsonp",
        "nothub__temptTag-2010_7_30_16_3_46.gml",
        "drawing.svg",
    )
] + [
    b"x,y,t,pen,stroke\n0,0,0,1,a\n1,1,0.1,1,a\n2,2,0.2,0,a\n\n3,3,0.3,1,b\n",
    b'{"traces": [{"xy": [[0, 0], [1, 1]], "t": [0, 1]}, {"xy": [[2, 2]], "t": [2]}]}',
    b"[[[0, 0], [1, 1]], [[2, 2]]]",
]


def check(read, data: bytes) -> None:
    """``read(data)`` returns valid traces on one clock, or raises a one-line InputError."""
    try:
        traces = read(data, "fuzz")
    except InputError as e:
        message = str(e)
        assert message.startswith("fuzz: ") and "\n" not in message, message
        return
    assert isinstance(traces, list) and traces
    assert all(isinstance(tr, Trace) and len(tr) >= 1 for tr in traces)
    assert all(np.all(np.isfinite(tr.xy)) for tr in traces)
    timed = [tr.t is not None for tr in traces]
    assert all(timed) or not any(timed)
    if timed[0]:
        assert traces[0].t[0] == 0.0
        clock = np.concatenate([tr.t for tr in traces])
        assert np.all(np.diff(clock) >= 0)


@FUZZ
@given(data=st.binary(max_size=3000), reader=st.sampled_from(READERS))
def test_any_bytes(data: bytes, reader) -> None:
    check(reader, data)


@FUZZ
@given(text=st.text(max_size=1000), reader=st.sampled_from(READERS))
def test_any_text(text: str, reader) -> None:
    check(reader, text.encode("utf-8", "surrogatepass"))


GML_TOKENS = [
    "<gml>", "</gml>", "<GML>", "</GML>", "<tag>", "</tag>", "<drawing>", "</drawing>",
    "<stroke>", "</stroke>", '<stroke isDrawing="false">', "<pt>", "</pt>", "<x>", "</x>",
    "<y>", "</y>", "<t>", "</t>", "<time>", "</time>", "<environment>", "</environment>",
    "<up>", "</up>", "<screenBounds>", "</screenBounds>", "<screenScale>", "</screenScale>",
    "0", "1", "0.5", "-1", "1.5", "0,25", "1e12", "1262304000000", "nan", "inf", "1e309", "x",
    "1e308", "-1e308", "640", "1e15",
    " ", "&amp;", "<!-- c -->", "<![CDATA[0.3]]>",
]  # fmt: skip


@FUZZ
@given(tokens=st.lists(st.sampled_from(GML_TOKENS), max_size=120))
def test_gml_token_soup(tokens: list[str]) -> None:
    check(read_gml, "".join(tokens).encode())
    check(read_traces_bytes, "".join(tokens).encode())


@FUZZ
@given(
    seed=st.sampled_from(SEEDS),
    edits=st.lists(
        st.tuples(st.sampled_from(["flip", "cut", "insert", "delete"]), st.integers(0, 1 << 20),
                  st.integers(0, 255)),
        min_size=1,
        max_size=8,
    ),
    reader=st.sampled_from(READERS),
)  # fmt: skip
def test_mutated_fixtures(seed: bytes, edits, reader) -> None:
    data = bytearray(seed)
    for op, pos, byte in edits:
        if not data:
            break
        i = pos % len(data)
        if op == "flip":
            data[i] ^= 1 << (byte % 8)
        elif op == "cut":
            del data[i:]
        elif op == "insert":
            data.insert(i, byte)
        else:
            del data[i]
    check(reader, bytes(data))


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(10**20), 10**20)
    | st.floats(allow_nan=False)
    | st.sampled_from(["0,5", "0.25", "1", "false", "<gml/>", "x"]),
    lambda children: st.lists(children, max_size=5)
    | st.dictionaries(
        st.sampled_from(["gml", "tag", "drawing", "stroke", "pt", "x", "y", "t", "time",
                         "isDrawing", "environment", "up", "screenBounds", "traces", "xy"]),
        children,
        max_size=5,
    ),
    max_leaves=40,
)  # fmt: skip


@FUZZ
@given(value=json_values)
def test_json_structures(value) -> None:
    check(lambda data, name: read_gml_json(value, name), b"")
    check(lambda data, name: read_points_json_object(value, name), b"")
    check(read_traces_bytes, json.dumps(value).encode())


CSV_TOKENS = [
    "x", "y", "t", "time", "pen", "stroke", ",", ";", "\t", " ", "\n", "\n\n", "#", '"',
    "0", "1", "-2.5", "0,5", "1e15", "1e16", "-1e308", "nan", "abc",
]  # fmt: skip


@FUZZ
@given(tokens=st.lists(st.sampled_from(CSV_TOKENS), max_size=150))
def test_csv_token_soup(tokens: list[str]) -> None:
    check(read_points_csv, "".join(tokens).encode())
    check(read_traces_bytes, "".join(tokens).encode())


PATH_TOKENS = ["M", "m", "L", "l", "H", "v", "C", "c", "S", "Q", "t", "A", "a", "Z", "z", "0", "1",
               "-5", "20", "0.5", "1e300", "1e15", "1e-300", ",", " ", "."]  # fmt: skip
TRANSFORMS = ["", "scale(1e300)", "scale(0)", "scale(1 -1)", "rotate(45)", "skewX(89.999)",
              "matrix(1 2 3 4 5 6)", "translate(1e15)", "scale(1e-300)"]  # fmt: skip
SHAPES = ['<circle r="{n}"/>', '<rect width="{n}" height="{n}" rx="{n}"/>', '<ellipse rx="{n}"/>',
          '<polyline points="{n} {n} {n},{n}"/>', '<line x2="{n}"/>']  # fmt: skip
NUMBERS = ["0", "-1", "3", "1e300", "1e15", "nan", "2mm", "5%", "1in", ""]


@FUZZ
@given(
    d=st.lists(st.sampled_from(PATH_TOKENS), max_size=60),
    transform=st.sampled_from(TRANSFORMS),
    shape=st.sampled_from(SHAPES),
    numbers=st.lists(st.sampled_from(NUMBERS), min_size=4, max_size=4),
    size=st.sampled_from(["", 'width="10mm" height="1e300in" ', 'viewBox="0 0 0 0" ']),
)
def test_svg_structures(d, transform, shape, numbers, size) -> None:
    body = shape.replace("{n}", "{}").format(*numbers[: shape.count("{n}")] * 2)
    svg = (
        f'<svg xmlns="http://www.w3.org/2000/svg" {size}><g transform="{transform}">'
        f'<path d="{"".join(d)}"/>{body}</g></svg>'
    )
    check(read_svg, svg.encode())
