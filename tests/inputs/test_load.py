"""load_traces: the format is sniffed from the content, the size is bounded, errors are one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tagbot.errors import InputError
from tagbot.inputs import (
    FORMATS,
    MAX_INPUT_BYTES,
    detect_format,
    load_traces,
    read_traces_bytes,
)

from .conftest import DATA

FIXTURES = {
    "spec10.gml": "gml",
    "legacy.gml": "gml",
    "sideways.gml": "gml",
    "fattag.gml": "gml",
    "restart.gml": "gml",
    "epoch_ms.gml": "gml",
    "truncated.gml": "gml",
    "book.json": "gml",
    "book_xml_string.jsonp": "gml",
    "canvasplayer__142.json": "gml",
    "nothub__temptTag-2010_7_30_16_3_46.gml": "gml",
    "drawing.svg": "svg",
}


def same(a, b) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x.xy, y.xy) and ((x.t is None and y.t is None) or np.array_equal(x.t, y.t))
        for x, y in zip(a, b, strict=True)
    )


@pytest.mark.parametrize("name", sorted(FIXTURES))
def test_fixtures_load_the_same_under_a_wrong_extension(name: str, tmp_path: Path) -> None:
    data = (DATA / name).read_bytes()
    assert detect_format(data) == FIXTURES[name] in FORMATS
    expected = load_traces(DATA / name)
    for wrong in ("tag.csv", "tag.svg", "tag.txt", "tag"):
        path = tmp_path / wrong
        path.write_bytes(data)
        assert same(load_traces(path), expected)
        assert same(read_traces_bytes(data, wrong), expected)


@pytest.mark.parametrize(
    ("data", "fmt"),
    [
        (b"x,y\n0,0\n", "csv"),
        (b"\n\n0.5,1\n", "csv"),
        (b"[[0, 0]]", "json"),
        (b'  {"traces": []}', "json"),
        (b'cb({"traces": [{"xy": [[0, 0]]}]})', "json"),
        (b'\xef\xbb\xbf{"gml": {}}', "gml"),
        (b"<?xml version='1.0'?>\n<!-- c -->\n<GML/>", "gml"),
        (b'<svg xmlns="http://www.w3.org/2000/svg"/>', "svg"),
        ('<?xml version="1.0" encoding="UTF-16"?><gml/>'.encode("utf-16"), "gml"),
    ],
)
def test_detect_format(data: bytes, fmt: str) -> None:
    assert detect_format(data) == fmt


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n",
         "not a GML, SVG, point or UNIPEN file (not UTF-8 text at byte 10; "
         "starts with '%PDF-1.4')"),
        (b"%PDF-1.4\n1 0 obj\n", "not a GML, SVG, point or UNIPEN file (starts with '%PDF-1.4')"),
        (b"", "empty file"),
        (b" \n\t", "empty file"),
        (b"<html><body/></html>", "not a GML, SVG, point or UNIPEN file (the XML root is <html>)"),
        (b'{"name": "x", "id": 3}', "JSON, but neither #000000book GML nor points "
         "(top-level fields: id, name)"),
        (b'{"model": "gamma", "plans": []}', "a tagbot plan file, not a recording (GML, SVG"
         " or points); plans are drawn, sampled or rendered as they are, not fitted"),
        (b"3", "not a GML, SVG, point or UNIPEN file (starts with '3')"),
        (b"hello world\n", "not a GML, SVG, point or UNIPEN file (starts with 'hello')"),
        (b"{oops", "not JSON (line 1, column 2: Expecting property name enclosed"),
    ],
)  # fmt: skip
def test_unknown_content_is_one_clear_line(data: bytes, message: str) -> None:
    with pytest.raises(InputError) as e:
        read_traces_bytes(data, "tag.gml")
    assert str(e.value).startswith(f"tag.gml: {message}")
    assert "\n" not in str(e.value)


def test_oversized_file_is_refused_before_reading(tmp_path: Path) -> None:
    path = tmp_path / "tag.gml"
    with open(path, "wb") as f:
        f.truncate(60 * 1024 * 1024)  # sparse: nothing is written, and nothing must be read
    with pytest.raises(InputError) as e:
        load_traces(path)
    assert str(e.value) == f"{path}: file is 60 MB, more than the 32 MB limit"


def test_oversized_bytes_are_refused() -> None:
    with pytest.raises(InputError, match="more than the 32 MB limit"):
        read_traces_bytes(b" " * (MAX_INPUT_BYTES + 1), "big")


def test_missing_file() -> None:
    with pytest.raises(InputError, match=r"^nowhere\.gml: cannot read \(No such file"):
        load_traces("nowhere.gml")
