"""UNIPEN: components, units, the sampling clock through pen lifts, segments, bounds and errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from tagbot.cli import main
from tagbot.errors import InputError
from tagbot.inputs import MAX_INPUT_BYTES, detect_format, load_traces, read_traces_bytes, unipen
from tagbot.inputs.unipen import MAX_RATE, load_unipen, parse_unipen, read_unipen

HEADER = (
    ".VERSION 1.0\n.COORD X Y\n.X_POINTS_PER_MM 10\n.Y_POINTS_PER_MM 20\n.POINTS_PER_SECOND 100\n"
)

WORD = (
    HEADER
    + ".START_SET\n.PEN_DOWN\n 10 -20\n 20 -40\n 30 -60\n"
    + ".PEN_UP\n 40 -60\n 50 -60\n"
    + ".COMMENT pen data ends at the next keyword\n"
    + ".PEN_DOWN\n 60 -80\n 70 -100\n"
)


def unp(text: str) -> bytes:
    return text.encode()


def error(data: bytes, name: str = "w.dat", components: str | None = None) -> str:
    with pytest.raises(InputError) as e:
        read_unipen(data, name, components)
    message = str(e.value)
    assert "\n" not in message and message.startswith(f"{name}: ")
    return message[len(name) + 2 :]


# --------------------------------------------------------------------------- reading


def test_one_trace_per_pen_down_in_mm_with_y_up() -> None:
    a, b = read_unipen(unp(WORD))
    assert a.xy.tolist() == [[1, -1], [2, -2], [3, -3]]  # x / 10, y / 20, y kept (it points up)
    assert b.xy.tolist() == [[6, -4], [7, -5]]


def test_clock_counts_pen_up_samples_so_a_lift_keeps_its_duration() -> None:
    a, b = read_unipen(unp(WORD))
    assert a.t.tolist() == [0.0, 0.01, 0.02]
    assert b.t.tolist() == [0.05, 0.06]  # samples 5 and 6: the two in-air samples count
    assert a.clock is not None and "POINTS_PER_SECOND 100" in a.clock


def test_time_is_zero_at_the_first_pen_down_point() -> None:
    data = unp(HEADER + ".PEN_UP\n0 0\n0 0\n0 0\n.PEN_DOWN\n10 20\n20 20\n")
    (tr,) = read_unipen(data)
    assert tr.t.tolist() == [0.0, 0.01]


def test_formats_are_told_from_the_content(tmp_path) -> None:
    path = tmp_path / "word.txt"
    path.write_bytes(unp(WORD))
    assert detect_format(unp(WORD)) == "unipen"
    for traces in (load_traces(path), read_traces_bytes(unp(WORD)), load_unipen(path)):
        assert [len(t) for t in traces] == [3, 2]


def test_round_trip_of_written_samples() -> None:
    rng = np.random.default_rng(3)
    raw = [np.round(rng.uniform(-5000, 5000, (n, 2)), 3) for n in (7, 1, 12)]
    text = ".COORD X Y\n.X_POINTS_PER_MM 50\n.Y_POINTS_PER_MM 40\n.POINTS_PER_SECOND 200\n"
    for block in raw:
        text += (
            ".PEN_DOWN\n" + "".join(f"{x!r} {y!r}\n" for x, y in block.tolist()) + ".PEN_UP\n1 1\n"
        )
    traces = read_unipen(unp(text))
    for tr, block in zip(traces, raw, strict=True):
        np.testing.assert_array_equal(tr.xy, block / np.array([50.0, 40.0]))
    starts = [0, 8, 10]  # every block is followed by one in-air sample
    for tr, start, block in zip(traces, starts, raw, strict=True):
        np.testing.assert_array_equal(tr.t, (start + np.arange(len(block))) / 200.0)


@pytest.mark.parametrize(
    ("units", "scale"),
    [
        (".X_POINTS_PER_INCH 254\n.Y_POINTS_PER_INCH 508\n", (10.0, 20.0)),
        (".X_POINTS_PER_MM 4\n", (4.0, 4.0)),  # one axis given: used for both
        (".Y_POINTS_PER_MM 5\n", (5.0, 5.0)),
        ("", (1.0, 1.0)),  # no resolution: the file's own unit
    ],
)
def test_units(units: str, scale: tuple[float, float]) -> None:
    (tr,) = read_unipen(unp(units + ".PEN_DOWN\n100 200\n300 -400\n"))
    assert tr.xy.tolist() == [[100 / scale[0], 200 / scale[1]], [300 / scale[0], -400 / scale[1]]]
    assert tr.t is None  # no rate and no T: untimed


def test_t_column_in_milliseconds_and_extra_columns_ignored() -> None:
    text = ".COORD X Y T P\n.PEN_DOWN\n1 2 1000 50\n3 4 1010 60\n.PEN_UP\n5 5 1100 0\n"
    text += ".PEN_DOWN\n6 7 1250 40\n"
    a, b = read_unipen(unp(text))
    assert a.xy.tolist() == [[1, 2], [3, 4]] and b.xy.tolist() == [[6, 7]]
    assert a.t.tolist() == [0.0, 0.01] and b.t.tolist() == [0.25]


def test_dt_adds_elided_milliseconds_to_the_sample_clock() -> None:
    text = ".POINTS_PER_SECOND 100\n.PEN_DOWN\n0 0\n1 1\n.DT 500\n.PEN_DOWN\n2 2\n.DT\n 250\n"
    text += ".PEN_DOWN\n3 3\n"
    a, b, c = read_unipen(unp(text))
    assert a.t.tolist() == [0.0, 0.01]
    assert b.t.tolist() == pytest.approx([0.52], abs=1e-15)
    assert c.t.tolist() == pytest.approx([0.78], abs=1e-15)
    # No time elided: the clock runs on as if the keyword were not there.
    a, b = read_unipen(unp(".POINTS_PER_SECOND 100\n.PEN_DOWN\n0 0\n.DT 0\n.PEN_DOWN\n1 1\n"))
    assert a.t.tolist() == [0.0] and b.t.tolist() == [0.01]


def test_samples_on_the_keyword_line_blank_lines_crlf_and_bom() -> None:
    text = "\ufeff.COORD X Y\r\n.PEN_DOWN 1 2\r\n\r\n 3 4\r\n.PEN_UP\r\n"
    (tr,) = read_unipen(text.encode())
    assert tr.xy.tolist() == [[1, 2], [3, 4]]


def test_single_instant_is_untimed() -> None:
    (tr,) = read_unipen(unp(".COORD X Y T\n.PEN_DOWN\n1 2 5\n3 4 5\n"))
    assert tr.t is None


def test_bounds_are_inclusive() -> None:
    (tr,) = read_unipen(unp(f".POINTS_PER_SECOND {MAX_RATE:g}\n.PEN_DOWN\n1e15 -1e15\n0 0\n"))
    assert tr.xy.tolist() == [[1e15, -1e15], [0, 0]] and tr.t.tolist() == [0, 1 / MAX_RATE]


def test_point_limit(monkeypatch) -> None:
    monkeypatch.setattr(unipen, "MAX_POINTS", 3)
    assert len(read_unipen(unp(".PEN_DOWN\n1 1\n2 2\n.PEN_UP\n3 3\n"))) == 1
    assert error(unp(".PEN_DOWN\n1 1\n2 2\n.PEN_UP\n3 3\n4 4\n")) == "line 6: more than 3 samples"


# --------------------------------------------------------------------------- segments


SEGMENTED = (
    ".COORD X Y\n.POINTS_PER_SECOND 100\n"
    '.SEGMENT WORD 0-2 OK "a \\"b\\""\n.SEGMENT CHARACTER ? GOOD\n.SEGMENT WORD 3\n'
    ".PEN_DOWN\n0 0\n1 0\n2 0\n.PEN_UP\n.PEN_UP\n3 0\n.PEN_DOWN\n4 0\n5 0\n6 0\n.PEN_DOWN\n7 0\n"
)


def test_segments_are_listed() -> None:
    segs = parse_unipen(unp(SEGMENTED)).segments
    assert [(s.kind, s.components, s.quality, s.label, s.line) for s in segs] == [
        ("WORD", "0-2", "OK", 'a "b"', 3),
        ("CHARACTER", None, "GOOD", None, 4),
        ("WORD", "3", None, None, 5),
    ]


def test_segment_labels_read_backslash_escapes() -> None:
    """In a label, \\n is a newline, \\t a tab, and a backslash before anything else is that
    character itself."""
    data = unp('.COORD X Y\n.SEGMENT WORD 0 OK "a\\nb\\tc\\\\d\\"e\\x"\n.PEN_DOWN\n0 0\n')
    (seg,) = parse_unipen(data).segments
    assert seg.label == 'a\nb\tc\\d"ex'


@pytest.mark.parametrize(
    ("spec", "points"),
    [
        ("0-2", [[0, 1, 2], [4, 5, 6]]),  # the empty .PEN_UP is not a component
        ("3", [[7]]),
        ("0:1-2:1", [[1, 2], [4, 5]]),
        ("2,0", [[0, 1, 2], [4, 5, 6]]),
        ("0:2-0:2,2:0-3", [[2], [4, 5, 6], [7]]),
        ("0:0-0:0,0:2-0:2", [[0], [2]]),  # one point left out splits a component in two
        ("-1", [[0, 1, 2]]),
        ("2-", [[4, 5, 6], [7]]),
    ],
)
def test_component_selection(spec: str, points: list[list[int]]) -> None:
    traces = read_unipen(unp(SEGMENTED), components=spec)
    assert [tr.xy[:, 0].tolist() for tr in traces] == points
    if spec == "3":  # one point: a single instant, untimed
        assert traces[0].t is None
    else:
        assert traces[0].t[0] == 0.0
    if spec == "0-2":
        assert traces[1].t.tolist() == [0.04, 0.05, 0.06]


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("4", "components '4': component 4 does not exist (the file has 4, numbered from 0)"),
        ("0-9", "component 9 does not exist"),
        ("0:3", "'0:3' is not A, A-B or A[:M]-B[:N]"),
        ("0:3-1", "point 3 is beyond the 3 points of the component on line 6"),
        ("2-0", "'2-0' runs backwards"),
        ("0:2-0:1", "'0:2-0:1' runs backwards"),
        ("a-b", "'a-b' is not A, A-B or A[:M]-B[:N]"),
        ("0,,1", "'' is not A, A-B"),
        ("1", "no points (components '1' are all pen-up)"),
    ],
)
def test_bad_selections(spec: str, message: str) -> None:
    assert message in error(unp(SEGMENTED), components=spec)


def test_load_unipen_reads_the_selected_components(tmp_path) -> None:
    path = tmp_path / "segmented.dat"
    path.write_bytes(unp(SEGMENTED))
    assert [tr.xy[:, 0].tolist() for tr in load_unipen(path, "3")] == [[7]]
    assert [tr.xy[:, 0].tolist() for tr in load_unipen(path, components="0:1-2:1")] == [
        [1, 2],
        [4, 5],
    ]
    assert len(load_unipen(path)) == 3  # every pen-down component


def test_load_unipen_names_the_file_in_its_errors(tmp_path) -> None:
    """An error in a UNIPEN file read from disk starts with that file's path and the line."""
    path = tmp_path / "bad.dat"
    path.write_bytes(unp(".COORD X Y X\n"))
    with pytest.raises(InputError) as e:
        load_unipen(path)
    assert str(e.value) == f"{path}: line 1: .COORD names X twice"


def test_selection_is_refused_when_sets_restart_the_numbering() -> None:
    data = unp(".START_SET a\n.PEN_DOWN\n0 0\n.START_SET b\n.PEN_DOWN\n1 1\n")
    assert len(read_unipen(data)) == 2
    assert "ambiguous: the file has 2 sets" in error(data, components="0")


def test_a_set_started_at_the_files_start_is_one_numbering_a_selection_can_use() -> None:
    """WORD opens with ``.START_SET`` before any pen data: its three components are one set,
    numbered 0-2, so component 2 (the second pen-down) is selected; a file with no pen data
    holds no set."""
    assert parse_unipen(unp(WORD)).sets == 1
    (trace,) = read_unipen(unp(WORD), components="2")
    assert trace.xy.tolist() == [[6, -4], [7, -5]]
    assert parse_unipen(unp(HEADER + ".START_SET\n")).sets == 0


def test_include_is_never_followed(tmp_path) -> None:
    (tmp_path / "data.dat").write_bytes(unp(WORD))
    index = tmp_path / "index.dat"
    index.write_bytes(unp('.VERSION 1.0\n.INCLUDE data.dat\n.SEGMENT WORD 0-2 OK "w"\n'))
    with pytest.raises(InputError) as e:
        load_traces(index)
    assert str(e.value) == (
        f"{index}: no pen data here; it includes 'data.dat', which tagbot does not follow "
        "(untrusted input): read that file instead"
    )
    assert parse_unipen(index.read_bytes()).includes == ("data.dat",)
    # with pen data of its own, the file reads as it is, the include ignored
    assert len(read_unipen(unp(".INCLUDE data.dat\n.PEN_DOWN\n1 1\n"))) == 1


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (".PEN_DOWN\n1 nan\n", "line 2: 'nan' is not a finite number"),
        (".PEN_DOWN\n1 inf\n", "line 2: 'inf' is not a finite number"),
        (".PEN_DOWN\n1e400 1\n", "line 2: '1e400' is not a finite number"),
        (".PEN_DOWN\n1_0 1\n", "line 2: '1_0' is not a finite number"),
        (".PEN_DOWN\n0x10 1\n", "line 2: '0x10' is not a finite number"),
        (".PEN_DOWN\n\u0663 1\n", "line 2: '\u0663' is not a finite number"),
        (".PEN_DOWN\n1,5 1\n", "line 2: '1,5' is not a finite number"),
        (".PEN_DOWN\n1.0000001e15 1\n", "line 2: '1.0000001e15' is out of range (at most 1e+15"),
        (".PEN_DOWN\n1e308 1\n", "line 2: '1e308' is out of range"),
        (".PEN_DOWN\n1\n", "line 2: expected x and y, got '1'"),
        (".COORD X Y\n.PEN_DOWN\n1 2 3\n", "line 3: expected 2 numbers (.COORD X Y), got 3"),
        (".COORD X T\n", "line 1: .COORD has no Y (got 'X T')"),
        (".COORD X Y X\n", "line 1: .COORD names X twice"),
        (".COORD X Y T\n.PEN_DOWN\n0 0 10\n0 0 9\n", "line 4: T decreases ('9' ms after 10.0"),
        (".POINTS_PER_SECOND 0\n", "line 1: .POINTS_PER_SECOND must be positive (got '0')"),
        (".POINTS_PER_SECOND -100\n", "line 1: .POINTS_PER_SECOND must be positive"),
        (".POINTS_PER_SECOND nan\n", "line 1: .POINTS_PER_SECOND is not a finite number"),
        (".POINTS_PER_SECOND\n", "line 1: .POINTS_PER_SECOND has no value"),
        (".POINTS_PER_SECOND 0,5\n", "line 1: .POINTS_PER_SECOND is not a finite number"),
        (f".POINTS_PER_SECOND {MAX_RATE * 1.01:g}\n",
         "line 1: .POINTS_PER_SECOND 1.01e+06 is above 1e+06 samples/s"),
        (".X_POINTS_PER_MM 0\n", "line 1: .X_POINTS_PER_MM must be positive"),
        (".Y_POINTS_PER_INCH 1e-16\n", "line 1: .Y_POINTS_PER_INCH 1e-16 is too small"),
        (".DT -5\n", "line 1: .DT is negative ('-5')"),
        (".VERSION 1.0\n.SEGMENT\n", "line 2: .SEGMENT has no type"),
        ('.VERSION 1.0\n\n.SEGMENT "only a label"\n', "line 3: .SEGMENT has no type"),
        (".X_POINTS_PER_MM 1e-15\n.PEN_DOWN\n1e15 0\n",
         "line 2: a sample is beyond ±1e+15 mm once converted"),
        # the component holding the far sample is named, not the one ending just before it
        (".X_POINTS_PER_MM 1e-15\n.PEN_DOWN\n0 0\n.PEN_UP\n1e15 0\n",
         "line 4: a sample is beyond ±1e+15 mm once converted"),
        (".POINTS_PER_SECOND 1e-15\n.PEN_DOWN\n0 0\n0 0\n0 0\n", "times beyond 1e+15 s"),
        (".PEN_DOWN\n1 1\n.X_POINTS_PER_MM 5\n.X_POINTS_PER_MM 6\n",
         "line 4: .X_POINTS_PER_MM changes after pen data (was 5 on line 3)"),
        (".COORD X Y\n.PEN_DOWN\n1 1\n.COORD X Y T\n", "line 4: .COORD changes after pen data"),
        (".VERSION 1.0\n.PEN_UP\n1 1\n", "no points (only .PEN_UP samples)"),
        (".VERSION 1.0\n.PEN_DOWN\n", "no points (no .PEN_DOWN samples)"),
    ],
)  # fmt: skip
def test_errors_name_the_line(text: str, message: str) -> None:
    assert error(unp(text)).startswith(message)


def test_times_up_to_the_largest_magnitude_are_read_beyond_it_refused() -> None:
    """At 3e-15 samples/s the fourth sample is 1e15 s in: the largest time read (exactly);
    a fifth is beyond it."""
    text = ".POINTS_PER_SECOND 3e-15\n.PEN_DOWN\n" + "0 0\n" * 4
    traces = read_unipen(unp(text), "w.dat")
    assert traces[0].t[-1] == 1e15
    assert error(unp(text + "0 0\n")) == "times beyond 1e+15 s"


def test_bytes_without_a_name_are_named_as_unipen_in_errors() -> None:
    for read in (parse_unipen, read_unipen):
        with pytest.raises(InputError) as e:
            read(unp(".COORD X Y\n.PEN_DOWN\n1 1\n.COORD X Y T\n"))
        assert str(e.value).startswith("<unipen>: line 4: .COORD changes after pen data")


@pytest.mark.parametrize("text", ["", "\n \n\t\n", "\ufeff\n", "\n" * 70 + ".PEN_DOWN\n"])
def test_text_whose_first_64_lines_are_blank_is_not_taken_for_unipen(text: str) -> None:
    """Only the first 64 lines are looked at (a bounded peek): blank ones say nothing."""
    assert not unipen.looks_like_unipen(text)
    assert unipen.looks_like_unipen("\n" * 63 + ".PEN_DOWN\n")
    assert not unipen.looks_like_unipen("\n" * 64 + ".PEN_DOWN\n")  # the 65th line


def test_only_a_byte_order_mark_is_skipped_before_the_first_keyword() -> None:
    assert unipen.looks_like_unipen("\ufeff.PEN_DOWN\n1 1\n")
    assert not unipen.looks_like_unipen("X.PEN_DOWN\n1 1\n")
    assert not unipen.looks_like_unipen("X\ufeff.PEN_DOWN\n1 1\n")


def test_a_unit_repeated_unchanged_after_pen_data_is_accepted() -> None:
    text = ".X_POINTS_PER_MM 5\n.PEN_DOWN\n10 20\n20 20\n.X_POINTS_PER_MM 5\n.PEN_DOWN\n30 30\n"
    assert [len(t) for t in read_unipen(unp(text))] == [2, 1]


def test_size_limit() -> None:
    data = unp(".PEN_DOWN\n") + b" " * (MAX_INPUT_BYTES - 10)
    assert error(data + b" ").startswith("file is 33 MB, more than the 32 MB limit")
    assert len(read_unipen(data.replace(b"\n ", b"\n1 2\n", 1)[:MAX_INPUT_BYTES])) == 1


def test_not_utf8() -> None:
    assert error(b".PEN_DOWN\n1 \xff\n").startswith("not a UNIPEN file (not UTF-8 text at byte 12)")


# --------------------------------------------------------------------------- command line


def test_tagbot_fit_reads_a_unipen_file(tmp_path, capsys) -> None:
    path = tmp_path / "word.dat"
    text = HEADER + ".PEN_DOWN\n" + "".join(f"{10 * i} {-20 * (i % 7)}\n" for i in range(60))
    path.write_bytes(unp(text))
    out = tmp_path / "plan.json"
    assert main(["fit", str(path), "-o", str(out)]) == 0
    plan = json.loads(out.read_text())
    assert plan["format"] == "tagbot-plan" and plan["plans"]
    err = capsys.readouterr().err
    assert f"{path}: 1 trace (60 points)" in err and "POINTS_PER_SECOND 100" in err


REFUSE = """
import json, sys
from tagbot.cli import main
code = main(sys.argv[1:])
heavy = sorted(m for m in ("numba", "scipy", "matplotlib") if m in sys.modules)
print(json.dumps({"code": code, "heavy": heavy}))
"""


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("bad.dat", ".COORD X Y\n.PEN_DOWN\n1 2\n3 nan\n", "line 4: 'nan' is not a finite number"),
        ("bad.gml", "<gml><tag><drawing><stroke><pt><x>1e400</x><y>0</y></pt></stroke></drawing>"
         "</tag></gml>", "<stroke> 1, <pt> 1: x is not a finite number ('1e400')"),
        ("bad.gml", "%PDF-1.4", "not a GML, SVG, point or UNIPEN file"),
    ],
)  # fmt: skip
def test_a_bad_file_is_refused_before_the_numeric_core_loads(
    tmp_path, name: str, content: str, message: str
) -> None:
    """Refusing is fast: in a fresh interpreter, numba, scipy and matplotlib never load."""
    path = tmp_path / name
    path.write_text(content)
    env = dict(os.environ)
    env.pop("TAGBOT_CHECK_KERNELS", None)  # the suite's kernel checks load numba on purpose
    proc = subprocess.run(
        [sys.executable, "-c", REFUSE, "fit", str(path)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    result = json.loads(proc.stdout)
    assert result == {"code": 2, "heavy": []}
    (line,) = proc.stderr.splitlines()
    assert line.startswith(f"tagbot: error: {path}: {message}")


def test_folders_in_corpus_mode_include_dat_files(tmp_path) -> None:
    from tagbot.corpus import expand_inputs, output_paths

    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "anton01.dat").write_bytes(unp(WORD))
    (tmp_path / "notes.md").write_text("no")
    (found,) = expand_inputs([str(tmp_path)])
    assert found.endswith("anton01.dat") and len(load_traces(found)) == 2
    assert output_paths([found], tmp_path / "out", ".json") == [
        str(tmp_path / "out" / "anton01.json")
    ]
