"""SVG: flattened curves lie on the true shapes within tolerance, units, transforms, y flipped,
and hostile files refused."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tagbot.errors import InputError
from tagbot.inputs import load_traces, read_svg
from tagbot.inputs.svg import MAX_SVG_ELEMENTS, SVG_FLATNESS_MM

from .conftest import DATA

TOL = SVG_FLATNESS_MM
SVG_NS = 'xmlns="http://www.w3.org/2000/svg"'


def mm_svg(body: str) -> bytes:
    """An SVG whose user unit is one millimetre."""
    return f'<svg {SVG_NS} width="200mm" height="100mm" viewBox="0 0 200 100">{body}</svg>'.encode()


def flipped(traces) -> list[np.ndarray]:
    """The traces back in SVG coordinates (y down)."""
    return [tr.xy * [1, -1] for tr in traces]


def chord_midpoints(p: np.ndarray) -> np.ndarray:
    return (p[1:] + p[:-1]) / 2


def test_fixture_drawing() -> None:
    traces = load_traces(DATA / "drawing.svg")
    assert len(traces) == 4 and all(tr.t is None for tr in traces)
    path, polyline, line, circle = flipped(traces)
    assert np.allclose(path[[0, -1]], [[10, 10], [10, 10]], atol=1e-3)  # closed
    assert np.allclose(polyline, [[10, 50], [30, 70], [50, 50]], atol=1e-3)
    assert np.allclose(line, [[150, 50], [150, 70]], atol=1e-3)  # translate(150,50) rotate(90)
    r = np.hypot(*(circle - [100, 70]).T)
    assert np.allclose(r, 15, atol=1e-3)


def test_y_is_flipped_and_units_are_mm() -> None:
    (tr,) = read_svg(mm_svg('<polyline points="10,20 30,40"/>'))
    assert np.allclose(tr.xy, [[10, -20], [30, -40]], atol=1e-3)


def test_user_units_are_css_pixels() -> None:
    (tr,) = read_svg(f'<svg {SVG_NS}><path d="M 0 0 L 96 0 L 96 48"/></svg>'.encode())
    assert np.allclose(tr.xy, [[0, 0], [25.4, 0], [25.4, -12.7]])


def test_lines_and_quadratic_bezier() -> None:
    # x is linear in the parameter, so the quadratic is the parabola y = 10 + 40 s (1 - s)
    (p,) = flipped(read_svg(mm_svg('<path d="M 10 10 L 50 10 Q 60 30 70 10"/>')))
    assert np.allclose(p[:2], [[10, 10], [50, 10]], atol=1e-3)
    q = p[1:]
    s = (q[:, 0] - 50) / 20
    assert np.allclose(q[:, 1], 10 + 40 * s * (1 - s), atol=1e-3)
    # the chords stay within the tolerance of the curve (sagitta of a parabola of y'' = -0.2)
    gaps = np.diff(q[:, 0])
    assert np.max(0.2 / 8 * gaps**2) <= TOL + 1e-9


def test_cubic_bezier() -> None:
    # control x evenly spaced → x linear in the parameter; y = 20 u³ with u = (x - 100) / 20
    (p,) = flipped(read_svg(mm_svg('<path d="M 80 -10 C 86.6667 10 93.3333 -10 100 10"/>')))
    # this is (2t - 1)³ scaled: control y values -1, 1, -1, 1 → 10·y around 0
    u = (p[:, 0] - 90) / 10
    assert np.allclose(p[:, 1], 10 * u**3, atol=2e-3)
    mid = chord_midpoints(p)
    um = (mid[:, 0] - 90) / 10
    assert np.max(np.abs(mid[:, 1] - 10 * um**3)) <= TOL + 2e-3


@pytest.mark.parametrize("sweep", [0, 1])
def test_arc_is_a_semicircle_within_tolerance(sweep: int) -> None:
    (p,) = flipped(read_svg(mm_svg(f'<path d="M 100 50 A 20 20 0 0 {sweep} 140 50"/>')))
    r = np.hypot(*(p - [120, 50]).T)
    assert np.allclose(r, 20, atol=1e-3)  # every vertex on the circle
    assert np.allclose(p[[0, -1]], [[100, 50], [140, 50]], atol=1e-3)
    sagitta = 20 - np.hypot(*(chord_midpoints(p) - [120, 50]).T)
    assert np.max(sagitta) <= TOL + 1e-6
    assert np.max(sagitta) > TOL / 4  # adaptive, not wastefully fine
    # sweep flag 1 turns clockwise on screen: through the top (y < 50 in SVG coordinates)
    assert np.all(p[1:-1, 1] < 50) if sweep else np.all(p[1:-1, 1] > 50)


def test_flattening_adapts_to_curvature() -> None:
    small = flipped(read_svg(mm_svg('<circle cx="50" cy="50" r="2"/>')))[0]
    large = flipped(read_svg(mm_svg('<circle cx="50" cy="50" r="50"/>')))[0]
    assert 5 < len(small) < len(large) < 200


def test_transform_group_and_shapes() -> None:
    body = (
        '<g transform="translate(100 50) scale(2)">'
        '<rect x="0" y="0" width="10" height="5"/>'
        '<g transform="rotate(90)"><polyline points="0,0 10,0"/></g>'
        '<ellipse cx="0" cy="0" rx="10" ry="5"/>'
        "</g>"
    )
    rect, line, ellipse = flipped(read_svg(mm_svg(body)))
    assert np.allclose(rect, [[100, 50], [120, 50], [120, 60], [100, 60], [100, 50]], atol=1e-3)
    assert np.allclose(line, [[100, 50], [100, 70]], atol=1e-3)
    e = (ellipse - [100, 50]) / [20, 10]
    assert np.allclose(np.hypot(*e.T), 1, atol=1e-4)


def test_subpaths_are_traces_and_moves_alone_are_dropped() -> None:
    traces = read_svg(mm_svg('<path d="M 0 0 L 10 0 M 20 20 M 30 30 l 5 0 z m 10 0 l 0 5"/>'))
    assert [len(tr) for tr in traces] == [2, 3, 2]
    assert np.allclose(flipped(traces)[2], [[40, 30], [40, 35]], atol=1e-3)


def test_path_data_without_an_initial_moveto_draws_nothing() -> None:
    traces = read_svg(mm_svg('<path d="L 5 5 Z"/><polyline points="0,0 1,1"/>'))
    assert len(traces) == 1


def test_external_dtd_is_not_fetched_and_is_fine() -> None:
    data = (
        b'<?xml version="1.0"?><!DOCTYPE svg PUBLIC "-//W3C//DTD SVG 1.1//EN" '
        b'"http://www.w3.org/Graphics/SVG/1.1/DTD/svg11.dtd">'
        + mm_svg('<polyline points="0,0 1,1"/>')
    )
    assert len(read_svg(data)) == 1


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("", "no points (no drawable shapes)"),
        ('<text x="1" y="1">hi</text>', "no points (no drawable shapes)"),
        ('<g id="a"><use href="#a"/></g>', "SVG <use> elements refer to themselves"),
        ('<polyline points="0,0 1e999,0"/>', "SVG coordinates are not finite or beyond 1e+15"),
        ('<path d="M 0 0 C 1e300 0 0 1e300 1 1"/>', "SVG coordinates are not finite or beyond"),
        ('<path d="M 0 0 A 1e14 1e14 0 0 1 2e14 0"/>', "SVG curves need more than"),
    ],
)
def test_svg_errors(body: str, message: str) -> None:
    with pytest.raises(InputError) as e:
        read_svg(mm_svg(body), "d.svg")
    assert str(e.value).startswith(f"d.svg: {message}")


def test_root_must_be_svg_and_complete() -> None:
    with pytest.raises(InputError, match=r"^d\.svg: not SVG \(the XML root is <gml>\)$"):
        read_svg(b"<gml/>", "d.svg")
    with pytest.raises(InputError, match=r"^d\.svg: SVG is cut off \("):
        read_svg(mm_svg('<polyline points="0,0 1,1"/>')[:-10], "d.svg")


def test_entity_bomb_is_refused_fast() -> None:
    entities = "".join(f'<!ENTITY e{k} "{f"&e{k - 1};" * 10 if k else "x"}">' for k in range(10))
    data = f"<!DOCTYPE svg [{entities}]><svg {SVG_NS}><text>&e9;</text></svg>".encode()
    start = time.perf_counter()
    with pytest.raises(InputError, match="entity declarations are refused"):
        read_svg(data, "d.svg")
    assert time.perf_counter() - start < 1.0


def test_use_bomb_is_refused_fast() -> None:
    layers = "".join(
        f'<g id="g{k}">' + f'<use href="#g{k - 1}"/>' * 10 + "</g>" for k in range(1, 10)
    )
    body = f'<defs><path id="g0" d="M0 0 L1 1"/>{layers}</defs><use href="#g9"/>'
    start = time.perf_counter()
    with pytest.raises(InputError, match=f"more than {MAX_SVG_ELEMENTS} elements through <use>"):
        read_svg(mm_svg(body), "d.svg")
    assert time.perf_counter() - start < 1.0


def test_use_references_are_drawn() -> None:
    body = '<defs><polyline id="p" points="0,0 10,0"/></defs><use href="#p" x="5" y="5"/>'
    (tr,) = read_svg(mm_svg(body))
    assert np.allclose(tr.xy * [1, -1], [[5, 5], [15, 5]], atol=1e-3)
