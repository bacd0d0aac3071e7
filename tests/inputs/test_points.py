"""Point files: CSV with or without a header, pen and stroke columns, tagbot motion CSV, JSON."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tagbot.errors import InputError
from tagbot.inputs import load_traces, read_points_csv, read_points_json


def xy(traces) -> list[list[list[float]]]:
    return [tr.xy.tolist() for tr in traces]


def times(traces) -> list[list[float] | None]:
    return [None if tr.t is None else np.round(tr.t, 12).tolist() for tr in traces]


# --------------------------------------------------------------------------- CSV


def test_header_with_time_and_blank_line_between_traces() -> None:
    traces = read_points_csv(b"x,y,t\n0,0,1.0\n1,2,1.1\n\n3,4,1.5\n5,6,1.6\n")
    assert xy(traces) == [[[0, 0], [1, 2]], [[3, 4], [5, 6]]]
    assert times(traces) == [[0, 0.1], [0.5, 0.6]]


def test_columns_in_any_order_case_and_extra_columns() -> None:
    traces = read_points_csv(b'"Time","Y","note","X"\n2,1,a,0\n3,5,b,4\n')
    assert xy(traces) == [[[0, 1], [4, 5]]] and times(traces) == [[0, 1]]


def test_pen_column_splits_traces_and_drops_pen_up_rows() -> None:
    data = b"x,y,pen\n0,0,1\n1,1,1\n9,9,0\n9,9,0\n2,2,1\n3,3,1.0\n7,7,0\n"
    assert xy(read_points_csv(data)) == [[[0, 0], [1, 1]], [[2, 2], [3, 3]]]


def test_stroke_column_splits_traces() -> None:
    data = b"stroke,x,y\na,0,0\na,1,1\nb,2,2\nb,3,3\na,4,4\n"
    assert xy(read_points_csv(data)) == [[[0, 0], [1, 1]], [[2, 2], [3, 3]], [[4, 4]]]
    assert len(read_points_csv(b"trace,x,y\n1,0,0\n2,1,1\n")) == 2


def test_headerless_two_and_three_columns() -> None:
    assert xy(read_points_csv(b"0,0\n1.5,-2\n")) == [[[0, 0], [1.5, -2]]]
    traces = read_points_csv(b"0,0,10\n1,1,10.25\n\n2,2,11\n")
    assert times(traces) == [[0, 0.25], [1]]


def test_other_separators_comments_and_bom() -> None:
    assert xy(read_points_csv(b"# made by hand\nx;y\n0,5;1,5\n")) == [[[0.5, 1.5]]]
    assert xy(read_points_csv(b"x\ty\n1\t2\n")) == [[[1, 2]]]
    assert xy(read_points_csv(b"1 2\n3   4\n")) == [[[1, 2], [3, 4]]]
    assert xy(read_points_csv(b"\xef\xbb\xbfx,y\r\n1,2\r\n")) == [[[1, 2]]]
    assert xy(read_points_csv(b"x,y\r1,2\r3,4\r")) == [[[1, 2], [3, 4]]]


def test_constant_time_means_untimed() -> None:
    assert times(read_points_csv(b"x,y,t\n0,0,0\n1,1,0\n")) == [None]


def test_tagbot_motion_csv_reads_as_its_pen_down_runs(tmp_path: Path) -> None:
    import tagbot
    from tagbot.io.motionfile import write_motion_csv

    tag = tagbot.load_plan(Path(tagbot.__file__).parent / "examples" / "cae.json")
    motion = tag.sample(0.01)
    path = tmp_path / "motion.csv"
    write_motion_csv(motion, path)
    traces = load_traces(path)
    runs = list(motion.runs())
    assert len(traces) == len(runs) == 3
    for tr, (_, rows) in zip(traces, runs, strict=True):
        assert np.allclose(tr.xy, motion.xy[rows], atol=1e-6)
        assert np.allclose(tr.t, motion.t[rows] - motion.t[0], atol=1e-9)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"x,y\n0,0\n1,abc\n", "points.csv: line 3: y is not a number ('abc')"),
        (b"x,y,t\n0,0,0\n1,1,nan\n", "points.csv: line 3: t is not a number ('nan')"),
        (b"x,y\n1e16,0\n", "points.csv: line 2: x is out of range ('1e16'; at most 1e+15 in"),
        (b"x,y\n0,0\n1\n", "points.csv: line 3: expected 2 fields, got 1"),
        (b"x,y,t\n0,0,1\n1,1,0.5\n", "points.csv: line 3: t decreases (0.5 after 1.0 on line 2)"),
        (b"x,y,pen\n0,0,2\n", "points.csv: line 2: pen is not 0 or 1 ('2')"),
        (b"x,z\n0,0\n", "points.csv: line 1: header has no y column (got 'x,z')"),
        (b"x,y,X\n0,0,0\n", "points.csv: line 1: column x appears twice"),
        (b"1,2,3,4\n", "points.csv: line 1: expected 2 or 3 numbers (x, y[, t]) without a header"),
        (b"x,y\n\n# nothing\n", "points.csv: no points"),
        (b"x,y,pen\n0,0,0\n", "points.csv: no points"),
        (b"x,y\n\xff\n", "points.csv: not a point file (not UTF-8 text at byte 4)"),
    ],
)
def test_csv_errors_name_the_line(data: bytes, message: str) -> None:
    with pytest.raises(InputError) as e:
        read_points_csv(data, "points.csv")
    assert str(e.value).startswith(message)


def test_decimal_comma_is_refused_with_comma_separators() -> None:
    with pytest.raises(InputError, match="expected 2 fields, got 3"):
        read_points_csv(b"x,y\n0,5,1\n", "p.csv")


# --------------------------------------------------------------------------- JSON


def test_json_one_trace() -> None:
    assert xy(read_points_json(b"[[0, 0], [1, 2.5]]")) == [[[0, 0], [1, 2.5]]]


def test_json_several_traces() -> None:
    traces = read_points_json(b"[[[0, 0], [1, 1]], [], [[2, 2]]]")
    assert xy(traces) == [[[0, 0], [1, 1]], [[2, 2]]]
    assert all(tr.t is None for tr in traces)


def test_json_traces_with_times() -> None:
    data = b'{"traces": [{"xy": [[0, 0], [1, 1]], "t": [3, 3.5]}, {"xy": [[2, 2]], "t": [4]}]}'
    traces = read_points_json(data)
    assert xy(traces) == [[[0, 0], [1, 1]], [[2, 2]]]
    assert times(traces) == [[0, 0.5], [1]]


def test_json_traces_without_times_and_jsonp() -> None:
    traces = read_points_json(b'cb({"traces": [{"xy": [[0, 0]]}]});')
    assert xy(traces) == [[[0, 0]]] and traces[0].t is None


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"[[0, 0], [1, NaN]]", "p.json: not JSON (NaN is not a finite number)"),
        (b"[[0, 0], [1, true]]", "p.json: [1]: expected [x, y] finite numbers (at most 1e+15 in "),
        (b'[[0, 0], [1, "2"]]', "p.json: [1]: expected [x, y] finite numbers"),
        (b"[[0, 0], [1, 2, 3]]", "p.json: [1]: expected [x, y] finite numbers"),
        (b"[[0, 0], [1, 1e999]]", "p.json: [1]: expected [x, y] finite numbers"),
        (b"[[0, 0], [1, 1e16]]", "p.json: [1]: expected [x, y] finite numbers"),
        (b'{"traces": [{"xy": [[0, 0]], "t": [-1e300]}]}', "p.json: traces[0].t[0]: expected a"),
        (b"[[[0, 0]], 5]", "p.json: [1]: expected a list of [x, y] points"),
        (b"[[[0, 0]], [[1, 1], [2]]]", "p.json: [1][1]: expected [x, y] finite numbers"),
        (b'{"traces": 3}', 'p.json: traces: expected a list of {"xy": [...]} objects'),
        (b'{"traces": [{"t": []}]}', 'p.json: traces[0]: expected an object with "xy"'),
        (
            b'{"traces": [{"xy": [[0, 0]], "t": [1, 2]}]}',
            "p.json: traces[0].t: expected a list of 1",
        ),
        (
            b'{"traces": [{"xy": [[0, 0]], "t": ["a"]}]}',
            "p.json: traces[0].t[0]: expected a finite",
        ),
        (
            b'{"traces": [{"xy": [[0, 0], [1, 1]], "t": [1, 0]}]}',
            "p.json: traces[0].t[1]: time decreases (0.0 after 1.0)",
        ),
        (
            b'{"traces": [{"xy": [[0, 0]], "t": [1]}, {"xy": [[1, 1]]}]}',
            "p.json: traces[1].t: missing while other traces have times",
        ),
        (
            b'{"traces": [{"xy": [[0, 0]], "t": [5]}, {"xy": [[1, 1]], "t": [4]}]}',
            "p.json: traces[1].t: starts before traces[0].t ends",
        ),
        (b"[]", "p.json: no points"),
        (b"[[], []]", "p.json: no points"),
        (b'"text"', "p.json: expected a list of points, of traces, or"),
        (b"[" * 100_000, "p.json: not JSON (nested too deeply)"),
    ],
)
def test_json_errors_name_the_item(data: bytes, message: str) -> None:
    with pytest.raises(InputError) as e:
        read_points_json(data, "p.json")
    assert str(e.value).startswith(message)
