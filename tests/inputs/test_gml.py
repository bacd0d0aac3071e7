"""GML: every quirk of the files found in the wild, orientation, scale, timing and hostile XML."""

from __future__ import annotations

import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tagbot.errors import InputError
from tagbot.inputs import SCALE_MM, load_traces, read_gml
from tagbot.inputs.gml import CLOCK_UNITS, read_gml_json

from .conftest import DATA, gml, stroke


def xy(traces) -> list[list[list[float]]]:
    return [np.round(tr.xy, 9).tolist() for tr in traces]


def times(traces) -> list[list[float] | None]:
    return [None if tr.t is None else np.round(tr.t, 9).tolist() for tr in traces]


# --------------------------------------------------------------------------- structure


def test_spec_1_0_layout() -> None:
    """Environment in the header, <t>, two tags and two drawings in order, pen-up skipped."""
    traces = load_traces(DATA / "spec10.gml")
    assert xy(traces) == [
        [[10, 80], [30, 80], [30, 40]],
        [[50, 40], [60, 60]],
        [[70, 80], [80, 75]],
        [[20, 20], [90, 10]],
    ]
    assert times(traces) == [[0, 0.1, 0.2], [0.5, 0.6], [1.0, 1.1], [1.5, 2.0]]


def test_legacy_layout() -> None:
    """<GML>, environment beside the header, mixed-case names, <time>, a one-point stroke."""
    traces = load_traces(DATA / "legacy.gml")
    assert xy(traces) == [[[20, 80], [40, 80], [50, 70], [60, 50]], [[70, 30]], [[10, 10], [20, 5]]]
    assert times(traces) == [[0, 0.1, 0.1, 0.2], [75.2], [75.5, 75.6]]


def test_scale_is_100_mm_per_unit() -> None:
    assert SCALE_MM == 100.0
    (tr,) = read_gml(gml(stroke((0.0, 1.0), (1.0, 0.0))))
    assert xy([tr]) == [[[0, 0], [100, 100]]]


@pytest.mark.parametrize("attr", ['isDrawing="false"', 'isdrawing="FALSE"', "ISDRAWING='0'"])
def test_pen_up_strokes_are_skipped(attr: str) -> None:
    data = gml(stroke((0.1, 0.1), (0.2, 0.2)), stroke((0.2, 0.2), (0.5, 0.5), attrs=" " + attr))
    assert len(read_gml(data)) == 1


def test_pen_down_attribute_values_keep_the_stroke() -> None:
    data = gml(stroke((0.1, 0.1), attrs=' isDrawing="true"'), stroke((0.2, 0.2)))
    assert len(read_gml(data)) == 2


def test_several_tags_and_drawings_concatenate_in_document_order() -> None:
    body = "".join(
        f"<tag><drawing>{stroke((0.1 * k, 0.5))}</drawing><drawing>{stroke((0.1 * k, 0.6))}"
        "</drawing></tag>"
        for k in range(1, 4)
    )
    traces = read_gml(f"<gml>{body}</gml>".encode())
    assert [tr.xy[0].round(9).tolist() for tr in traces] == [
        [10, 50], [10, 40], [20, 50], [20, 40], [30, 50], [30, 40]
    ]  # fmt: skip


def test_z_pressure_and_unknown_elements_are_ignored() -> None:
    data = gml(
        "<stroke><brush><name>fat</name></brush>"
        "<pt><x>0.1</x><y>0.2</y><z>7</z><pres>0.3</pres><thick>2</thick><rot>1</rot></pt></stroke>"
    )
    assert xy(read_gml(data)) == [[[10, 80]]]


def test_namespaced_elements() -> None:
    data = (
        b'<g:gml xmlns:g="urn:x"><g:tag><g:drawing><g:stroke><g:pt><g:x>0.5</g:x><g:y>0.5</g:y>'
        b"</g:pt></g:stroke></g:drawing></g:tag></g:gml>"
    )
    assert xy(read_gml(data)) == [[[50, 50]]]


def test_points_without_numbers_are_skipped() -> None:
    data = gml(stroke((0.1, 0.1), ("abc", 0.2), ("", 0.3), (0.5, 0.5)))
    data = data.replace(b"</stroke>", b"<pt><x>0.6</x></pt></stroke>")
    assert xy(read_gml(data)) == [[[10, 90], [50, 50]]]


@pytest.mark.parametrize(
    ("pt", "message"),
    [
        ((0.3, "nan"), "<stroke> 2, <pt> 2: y is not a finite number ('nan')"),
        (("NaN", 0.3), "<stroke> 2, <pt> 2: x is not a finite number ('NaN')"),
        ((0.4, "-inf"), "<stroke> 2, <pt> 2: y is not a finite number ('-inf')"),
        (("Infinity", 0.4), "<stroke> 2, <pt> 2: x is not a finite number ('Infinity')"),
        (("1e400", 0.4), "<stroke> 2, <pt> 2: x is not a finite number ('1e400')"),
        (("1e308", 0.4), "<stroke> 2, <pt> 2: x is out of range ('1e308'; at most 1e+15 in "
         "magnitude)"),
        ((0.4, "-1,5e16"), "<stroke> 2, <pt> 2: y is out of range ('-1,5e16'; at most 1e+15"),
        ((0.4, 0.4, "nan"), "<stroke> 2, <pt> 2: t is not a finite number ('nan')"),
        ((0.4, 0.4, "1e16"), "<stroke> 2, <pt> 2: t is out of range ('1e16'"),
    ],
)  # fmt: skip
def test_unusable_numbers_are_refused_naming_the_point(pt: tuple, message: str) -> None:
    """NaN, infinities and magnitudes beyond 10¹⁵ are refused, as the point-file reader does."""
    data = gml(stroke((0.1, 0.1, 0.0)), stroke((0.2, 0.2, 0.1), pt))
    with pytest.raises(InputError) as e:
        read_gml(data, "tag.gml")
    assert str(e.value).startswith(f"tag.gml: {message}")
    assert "\n" not in str(e.value)


def test_unusable_time_element_is_refused() -> None:
    data = gml(stroke((0.1, 0.1, 0.0))).replace(b"<t>0.0</t>", b"<time>inf</time>")
    with pytest.raises(InputError, match=r"<stroke> 1, <pt> 1: time is not a finite number"):
        read_gml(data, "tag.gml")


def test_largest_magnitude_is_still_read() -> None:
    """10¹⁵ itself is a usable coordinate and time (the bound is inclusive)."""
    (tr,) = read_gml(gml(stroke((0.1, 0.1, 0.0), ("1e15", "-1e15", "1e15"))))
    assert len(tr) == 2


def test_unusable_numbers_in_000000book_json_are_refused() -> None:
    pts = b'[{"x": 0.1, "y": 0.2}, {"x": 1e400, "y": 0}]'
    data = b'{"gml": {"tag": {"drawing": {"stroke": {"pt": ' + pts + b"}}}}}"
    with pytest.raises(InputError, match=r"tag.json: <stroke> 1, <pt> 2: x is not a finite number"):
        read_gml(data, "tag.json")


def test_decimal_commas() -> None:
    assert xy(read_gml(gml(stroke(("0,25", "0,5", "1,5"))))) == [[[25, 50]]]


def test_single_point_file_is_kept() -> None:
    (tr,) = read_gml(gml(stroke((0.3, 0.4, 0.0))))
    assert xy([tr]) == [[[30, 60]]] and tr.t is None


@pytest.mark.parametrize(
    ("data", "why"),
    [
        (gml(), "no <pt> elements"),
        (gml("<stroke></stroke>"), "no <pt> elements"),
        (gml(stroke((0.1, 0.1), attrs=' isDrawing="false"')), "only pen-up strokes"),
        (gml(stroke(("x", "y"), ("", ""))), "2 <pt> elements, none with numeric <x> and <y>"),
        (b"<GML/>", "no <pt> elements"),
    ],
)
def test_files_without_points_are_errors(data: bytes, why: str) -> None:
    with pytest.raises(InputError, match=rf"^tag\.gml: no points \({why}\)$"):
        read_gml(data, "tag.gml")


def test_environment_only_file() -> None:
    path = DATA / "environment_only.gml"
    with pytest.raises(InputError) as e:
        load_traces(path)
    assert str(e.value) == f"{path}: no points (no <pt> elements)"


def test_root_must_be_gml() -> None:
    with pytest.raises(
        InputError, match=r"^t\.xml: not GML \(the XML root is <tags>, not <gml>\)$"
    ):
        read_gml(b"<tags><tag/></tags>", "t.xml")


def test_malformed_xml_is_an_error() -> None:
    with pytest.raises(InputError, match=r"^t\.gml: not well-formed XML \(mismatched tag: line 1"):
        read_gml(b"<gml><tag></drawing></tag></gml>", "t.gml")


def test_junk_after_the_root_element_is_ignored() -> None:
    assert len(read_gml(gml(stroke((0.1, 0.1))) + b"\n<junk>\x00")) == 1


# --------------------------------------------------------------------------- truncation


def test_truncated_file_keeps_the_complete_points() -> None:
    traces = load_traces(DATA / "truncated.gml")
    assert xy(traces) == [[[10, 90], [20, 80]], [[30, 70], [40, 60]]]
    assert times(traces) == [[0, 0.1], [0.5, 0.6]]


def test_every_cut_of_a_file_keeps_a_prefix_of_its_points() -> None:
    data = (DATA / "spec10.gml").read_bytes()
    whole = np.concatenate([tr.xy for tr in read_gml(data)])
    for cut in range(len(data)):
        try:
            traces = read_gml(data[:cut], "cut.gml")
        except InputError as e:
            assert str(e).startswith("cut.gml: ")
            continue
        got = np.concatenate([tr.xy for tr in traces])
        assert np.array_equal(got, whole[: len(got)])


def test_truncated_before_any_point() -> None:
    with pytest.raises(InputError, match=r"^t\.gml: no points \(1 <pt> element, none with numeric"):
        read_gml(b"<GML><tag><drawing><stroke><pt><x>0.1</x><y>0.1</y>", "t.gml")
    with pytest.raises(InputError, match=r"^t\.gml: no points \(no <pt> elements; XML truncated: "):
        read_gml(b"<GML><tag><drawing><str", "t.gml")
    with pytest.raises(InputError, match=r"the XML ends before its root element; XML truncated"):
        read_gml(b"<?xml version='1.0'?>\n<GM", "t.gml")


# --------------------------------------------------------------------------- orientation/scale


def upright(data_points, up=None, bounds=None, screen_scale=None) -> list[list[float]]:
    env = ""
    if up is not None:
        env += f"<up><x>{up[0]}</x><y>{up[1]}</y><z>0</z></up>"
    if bounds is not None:
        env += f"<screenBounds><x>{bounds[0]}</x><y>{bounds[1]}</y></screenBounds>"
    if screen_scale is not None:
        env += f"<screenScale>{screen_scale}</screenScale>"
    return np.concatenate([tr.xy for tr in read_gml(gml(stroke(*data_points), environment=env))])


@pytest.mark.parametrize(
    ("up", "expected"),
    [
        ((0, -1), [[10, 80], [30, 60]]),  # the default: screen-up is up, y flips
        ((1, 0), [[20, 10], [40, 30]]),  # sideways: screen x points up
        ((-1, 0), [[80, 90], [60, 70]]),  # sideways the other way
        ((0, 1), [[90, 20], [70, 40]]),  # upside down
        ((0.98, -0.1), [[20, 10], [40, 30]]),  # accelerometer jitter snaps to the axis
    ],
)
def test_up_vector_turns_the_drawing_upright(up, expected) -> None:
    assert np.allclose(upright([(0.1, 0.2), (0.3, 0.4)], up=up), expected)


def test_sideways_letter_reads_upright() -> None:
    """An L captured sideways: its stem is vertical, on the left, and its foot points right."""
    (tr,) = load_traces(DATA / "sideways.gml")
    assert np.allclose(tr.xy, [[20, 90], [20, 10], [120, 10]])


def test_y_beyond_one_without_up_is_a_sideways_capture() -> None:
    pts = [(0.9, 0.2), (0.1, 0.2), (0.1, 1.2)]
    assert np.allclose(upright(pts), [[20, 90], [20, 10], [120, 10]])
    # an explicit up vector wins over the heuristic
    assert np.allclose(upright(pts, up=(0, -1)), [[90, 80], [10, 80], [10, -20]])


def test_per_axis_normalised_capture_is_stretched_to_the_screen_aspect() -> None:
    (tr,) = load_traces(DATA / "fattag.gml")
    assert np.allclose(tr.xy, [[15, 90], [15, 10], [120, 10]])


def test_stretch_follows_the_screen_bounds_of_the_upright_drawing() -> None:
    pts = [(0.2, 0.2), (0.6, 0.8)]
    assert np.allclose(upright(pts, bounds=(1000, 500)), [[40, 80], [120, 20]])
    assert np.allclose(upright(pts, bounds=(500, 1000)), [[20, 160], [60, 40]])
    assert np.allclose(upright(pts, bounds=(700, 700)), [[20, 80], [60, 20]])
    assert np.allclose(upright(pts, bounds=(0, 700)), [[20, 80], [60, 20]])


def test_no_stretch_for_uniformly_normalised_files() -> None:
    # beyond 0..1: divided by the short side
    assert np.allclose(
        upright([(0.2, 0.2), (0.6, 1.4)], up=(0, -1), bounds=(320, 480))[1], [60, -40]
    )
    # an axis spanning exactly 0..1: normalised to the drawing's bounding box (EyeWriter)
    assert np.allclose(upright([(0.0, 0.1), (1.0, 0.5)], bounds=(1000, 500)), [[0, 90], [100, 50]])
    # GML4U's screenScale: one length for both axes
    pts = [(0.2, 0.2), (0.6, 0.5)]
    assert np.allclose(upright(pts, bounds=(1240, 768), screen_scale=1240), [[20, 80], [60, 50]])


def test_pixel_coordinates_are_scaled_to_100_mm() -> None:
    got = upright([(0, 0), (640, 0), (640, 320)])
    assert np.allclose(got, [[0, 50], [100, 50], [100, 0]])


# --------------------------------------------------------------------------- timing


def gml_times(*strokes_times, time_tag="t") -> list[list[float] | None]:
    strokes = [
        stroke(*[(0.1 + 0.01 * i, 0.5, v) for i, v in enumerate(ts)], time_tag=time_tag)
        for ts in strokes_times
    ]
    return times(read_gml(gml(*strokes)))


def test_time_and_t_elements() -> None:
    assert gml_times([1.0, 1.5], time_tag="time") == [[0, 0.5]]
    assert gml_times([1.0, 1.5], time_tag="t") == [[0, 0.5]]


def test_t_is_relative_to_the_first_point_of_the_file_and_keeps_gaps() -> None:
    assert gml_times([10.0, 10.5], [12.0, 12.25]) == [[0, 0.5], [2.0, 2.25]]


def test_missing_times_make_the_file_untimed() -> None:
    assert gml_times([None, None], [None]) == [None, None]


def test_all_zero_times_make_the_file_untimed() -> None:
    assert gml_times([0, 0], [0.0, "0.000000"]) == [None, None]


def test_leading_missing_times_read_as_zero_as_gml4u_omits_zero() -> None:
    assert gml_times([None, 0.021, 0.022]) == [[0, 0.021, 0.022]]
    assert gml_times([None], [None, 0.5]) == [[0], [0, 0.5]]


def test_a_missing_time_after_a_timed_point_makes_the_file_untimed() -> None:
    assert gml_times([0.5, None, 0.7]) == [None]
    assert gml_times([0.5, 0.7], [None, None]) == [None, None]


def test_unreadable_time_makes_the_file_untimed() -> None:
    assert gml_times([0.1, "soon", 0.3]) == [None]


def test_epoch_milliseconds() -> None:
    traces = load_traces(DATA / "epoch_ms.gml")
    assert times(traces) == [[0, 0.016, 0.033], [1.0, 1.5]]


def test_epoch_seconds() -> None:
    assert gml_times([1262304000.0, 1262304000.5], [1262304002.0]) == [[0, 0.5], [2.0]]


def test_epoch_mixed_with_small_times_is_untimed() -> None:
    assert gml_times([None, 1262304000.5, 1262304001.0]) == [None]
    assert gml_times([1262304000000, 16]) == [None]


def test_duplicate_times_and_stalls_are_kept() -> None:
    assert gml_times([0.0, 0.1, 0.1, 0.2, 90.2]) == [[0, 0.1, 0.1, 0.2, 90.2]]


def test_time_decreasing_inside_a_stroke_makes_the_file_untimed() -> None:
    assert gml_times([0.0, 0.2, 0.1], [0.3, 0.4]) == [None, None]


def test_clock_restarts_between_strokes_are_chained() -> None:
    """The restarted stroke starts when the previous one ended; later strokes keep their gaps."""
    assert gml_times([5.0, 6.0], [0.0, 1.0], [3.0, 4.0]) == [[0, 1], [1, 2], [4, 5]]


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.lists(st.floats(0, 9e7, allow_subnormal=False), min_size=1, max_size=5).map(sorted),
        min_size=1,
        max_size=6,
    )
)
def test_chained_clock_never_decreases_and_keeps_stroke_timing(strokes_times) -> None:
    strokes = [stroke(*[(0.5, 0.5, repr(v)) for v in ts]) for ts in strokes_times]
    traces = read_gml(gml(*strokes))
    scale = 1.0 + sum(ts[-1] for ts in strokes_times)
    if traces[0].t is None:  # only when nothing moves on the chained clock (to rounding)
        assert all(ts[-1] - ts[0] <= 1e-12 * scale for ts in strokes_times)
        return
    clock = np.concatenate([tr.t for tr in traces])
    assert clock[0] == 0.0 and np.all(np.diff(clock) >= 0)
    unit = dict(CLOCK_UNITS)[traces[0].clock.split(":")[0].split()[0]]  # read from the rate
    for tr, ts in zip(traces, strokes_times, strict=True):
        assert np.allclose(np.diff(tr.t), np.diff(ts) * unit, rtol=0, atol=1e-12 * scale * unit)


def test_eyewriter_clocks_restart_in_every_drawing() -> None:
    traces = load_traces(DATA / "restart.gml")
    assert times(traces) == [[0, 2], [5, 6], [6, 7], [10, 10.5]]
    assert xy(traces) == [
        [[0, 100], [100, 100]],
        [[100, 50], [50, 75]],
        [[0, 50], [20, 50]],
        [[30, 70], [40, 70]],
    ]


# --------------------------------------------------------------------------- #000000book JSON


def test_book_json_with_collapsed_lists_strings_and_decimal_commas() -> None:
    traces = load_traces(DATA / "book.json")
    assert xy(traces) == [[[10, 80], [30, 80]], [[50, 50]]]
    assert times(traces) == [[0, 0.1], [0.5]]


def test_book_jsonp_holding_xml_as_a_string() -> None:
    traces = load_traces(DATA / "book_xml_string.jsonp")
    assert xy(traces) == [[[10, 90], [20, 70]]]
    assert times(traces) == [[0, 0.25]]


def test_book_json_shapes_read_alike() -> None:
    pt = {"x": 0.1, "y": 0.2, "time": 1}
    tag = {"drawing": {"stroke": {"pt": pt}}}
    for obj in (
        {"gml": {"tag": tag}},
        {"gml": {"tag": [tag]}},
        {"GML": {"tag": {"drawing": [{"stroke": [{"pt": [pt]}]}]}}},
        {"tag": tag},
        {"gml": '<gml><tag><drawing><stroke><pt><x>0.1</x><y>0.2</y><time>1</time></pt>'
         "</stroke></drawing></tag></gml>"},
    ):  # fmt: skip
        assert xy(read_gml_json(obj, "b.json")) == [[[10, 80]]], obj


def test_book_json_pen_up_as_a_field() -> None:
    obj = {"gml": {"tag": {"drawing": {"stroke": [
        {"pt": [{"x": 0.1, "y": 0.1}]},
        {"isDrawing": False, "pt": [{"x": 0.2, "y": 0.2}]},
        {"@isDrawing": "false", "pt": [{"x": 0.3, "y": 0.3}]},
    ]}}}}  # fmt: skip
    assert xy(read_gml_json(obj, "b.json")) == [[[10, 90]]]


def test_real_book_jsonp_capture() -> None:
    """canvasplayer 142 (public domain): a DustTag capture without <up>, y up to 1.35."""
    traces = load_traces(DATA / "canvasplayer__142.json")
    assert [len(tr) for tr in traces] == [27, 42, 72, 69, 60, 60]
    assert traces[0].t is not None and traces[0].t[0] == 0.0
    assert traces[-1].t[-1] == pytest.approx(6.05, abs=0.01)
    points = np.concatenate([tr.xy for tr in traces])
    # turned upright: the long screen side (y, up to 1.35) is horizontal
    width, height = np.ptp(points, axis=0)
    assert width == pytest.approx(123.1, abs=0.1) and height == pytest.approx(86.3, abs=0.1)


def test_real_eyewriter_capture() -> None:
    """nothub (MIT): EyeWriter clicks; the clock restarts in the second drawing and counts
    milliseconds (points about 19 ms apart: as seconds the tag would last 6 minutes)."""
    traces = load_traces(DATA / "nothub__temptTag-2010_7_30_16_3_46.gml")
    assert [len(tr) for tr in traces] == [4, 3, 2, 2]
    assert times(traces)[2] == [0.252953018, 0.267328018]  # restarted at 0, chained
    assert traces[0].clock.startswith("milliseconds: median sample interval 19 ")
    points = np.concatenate([tr.xy for tr in traces])
    assert np.allclose(points.min(axis=0), [0.0, 38.5013], atol=1e-3)
    assert np.allclose(points.max(axis=0), [100.0, 100.0])


@pytest.mark.parametrize("obj", [[], {"tags": []}, {"tag": 3}, "text"])
def test_json_that_is_not_book_gml(obj) -> None:
    with pytest.raises(InputError, match=r"^b\.json: JSON but not #000000book GML"):
        read_gml_json(obj, "b.json")


def test_truncated_book_json_is_an_error() -> None:
    data = (DATA / "book.json").read_bytes()[:200]
    with pytest.raises(InputError, match=r"^b\.json: not JSON \(line \d+, column \d+: "):
        read_gml(data, "b.json")


# --------------------------------------------------------------------------- hostile XML


def billion_laughs() -> bytes:
    entities = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{k} "{f"&lol{k - 1};" * 10}">' for k in range(1, 10)
    ]
    return f'<?xml version="1.0"?><!DOCTYPE gml [{"".join(entities)}]><gml>&lol9;</gml>'.encode()


def test_billion_laughs_fails_fast() -> None:
    start = time.perf_counter()
    with pytest.raises(InputError) as e:
        read_gml(billion_laughs(), "tag.gml")
    assert time.perf_counter() - start < 1.0
    assert str(e.value) == "tag.gml: XML entity declarations are refused (untrusted input)"


@pytest.mark.parametrize(
    "doctype",
    [
        '<!DOCTYPE gml [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>',
        '<!DOCTYPE gml [<!ENTITY % p SYSTEM "file:///etc/passwd"> %p;]>',
        '<!DOCTYPE gml [<!ENTITY xxe "small">]>',
    ],
)
def test_external_and_internal_entities_are_refused(doctype: str) -> None:
    data = f'<?xml version="1.0"?>{doctype}<gml><tag><drawing><stroke><pt><x>&xxe;</x>'
    data += "<y>0.1</y></pt></stroke></drawing></tag></gml>"
    with pytest.raises(InputError) as e:
        read_gml(data.encode(), "tag.gml")
    assert str(e.value) == "tag.gml: XML entity declarations are refused (untrusted input)"
    assert "root:" not in str(e.value)


def test_undefined_entity_is_an_error_not_a_lookup() -> None:
    with pytest.raises(InputError, match=r"not well-formed XML \(undefined entity"):
        read_gml(b"<gml><tag>&xxe;</tag></gml>")


def test_hostile_xml_inside_book_json_is_refused() -> None:
    inner = billion_laughs().decode().replace('"', '\\"')
    with pytest.raises(InputError, match="entity declarations are refused"):
        read_gml(f'{{"tag": {{"gml": "{inner}"}}}}'.encode(), "b.json")


def test_deeply_nested_xml_is_handled() -> None:
    depth = 100_000
    data = b"<gml>" + b"<a>" * depth + b"</a>" * depth + b"</gml>"
    with pytest.raises(InputError, match="no points"):
        read_gml(data)
