"""Motion CSV: exact header, round trip at the written precision, and clear read errors."""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from tagbot.errors import InputError
from tagbot.io.motionfile import HEADER, read_motion_csv, write_motion_csv


@dataclass
class FakeMotion:
    t: np.ndarray
    xy: np.ndarray
    v: np.ndarray
    speed: np.ndarray
    pen: np.ndarray


def fake_motion(n: int = 50) -> FakeMotion:
    rng = np.random.default_rng(7)
    v = rng.normal(scale=100.0, size=(n, 2))
    return FakeMotion(
        t=1.5 + 0.01 * np.arange(n),
        xy=rng.uniform(-200.0, 200.0, size=(n, 2)),
        v=v,
        speed=np.hypot(v[:, 0], v[:, 1]),
        pen=(np.arange(n) % 7 != 0).astype(np.int8),
    )


def test_header_and_rows_are_exact() -> None:
    m = FakeMotion(
        t=np.array([0.0, 0.01]),
        xy=np.array([[1.0, -2.5], [1.0 / 3.0, 1e-12]]),
        v=np.array([[0.0, 0.0], [-0.0, 123456789.125]]),
        speed=np.array([0.0, 123456789.125]),
        pen=np.array([1, 0], dtype=np.int8),
    )
    f = io.StringIO()
    write_motion_csv(m, f)
    assert f.getvalue() == (
        "t,x,y,vx,vy,speed,pen\n"
        "0,1,-2.5,0,0,0,1\n"
        "0.01,0.3333333333,1e-12,-0,123456789.1,123456789.1,0\n"
    )


def test_round_trip_to_ten_significant_digits(tmp_path: Path) -> None:
    m = fake_motion()
    path = tmp_path / "motion.csv"
    write_motion_csv(m, path)
    back = read_motion_csv(path)
    assert len(back) == len(m.t)
    for name in ("t", "xy", "v", "speed"):
        assert np.allclose(getattr(back, name), getattr(m, name), rtol=1e-9, atol=0), name
    assert back.pen.dtype == np.int8
    assert np.array_equal(back.pen, m.pen)
    with open(path, encoding="utf-8") as f:
        assert read_motion_csv(f).t.shape == m.t.shape


def test_empty_motion_has_only_the_header(tmp_path: Path) -> None:
    empty = FakeMotion(np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    path = tmp_path / "empty.csv"
    write_motion_csv(empty, path)
    assert path.read_text(encoding="utf-8") == HEADER + "\n"
    assert len(read_motion_csv(path)) == 0


def test_writer_refuses_inconsistent_or_non_finite_motion() -> None:
    m = fake_motion()
    m.speed = m.speed[:-1]
    with pytest.raises(ValueError, match="inconsistent shapes"):
        write_motion_csv(m, io.StringIO())
    m = fake_motion()
    m.v[3, 1] = np.nan
    with pytest.raises(ValueError, match="vy is not finite at sample 3"):
        write_motion_csv(m, io.StringIO())


GOOD = HEADER + "\n0,1,2,3,4,5,1\n0.01,1,2,3,4,5,0\n"


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("", r"m\.csv: empty"),
        ("t,x,y\n0,1,2\n", r"m\.csv:1: expected header 't,x,y,vx,vy,speed,pen', got 't,x,y'"),
        (HEADER + "\n0,1,2,3,4,5\n", r"m\.csv:2: expected 7 fields, got 6"),
        (HEADER + "\n0,1,2,abc,4,5,1\n", r"m\.csv:2: vx: expected a finite number, got 'abc'"),
        (HEADER + "\n0,1,2,3,nan,5,1\n", r"m\.csv:2: vy: expected a finite number, got 'nan'"),
        (HEADER + "\n0,1,2,3,4,inf,1\n", r"m\.csv:2: speed: expected a finite number"),
        (HEADER + "\n0,1_0,2,3,4,5,1\n", r"m\.csv:2: x: expected a finite number"),
        (HEADER + "\n0,1,2,3,4,5,2\n", r"m\.csv:2: pen: expected 0 or 1, got '2'"),
        (HEADER + "\n0,1,2,3,4,5,1.0\n", r"m\.csv:2: pen: expected 0 or 1"),
        (GOOD + "0.01,1,2,3,4,5,1\n", r"m\.csv:4: t: not increasing"),
        (HEADER + "\n0,1,2,3,4,5,1\n\n0.01,1,2,3,4,5,0\n", r"m\.csv:3: blank line"),
    ],
)
def test_read_errors_name_file_line_and_column(text: str, pattern: str, tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=pattern) as e:
        read_motion_csv(path)
    assert "\n" not in str(e.value)


def test_reader_accepts_crlf_and_trailing_blank_lines(tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    path.write_bytes(GOOD.replace("\n", "\r\n").encode() + b"\r\n\r\n")
    assert len(read_motion_csv(path)) == 2


def test_missing_motion_file_names_the_path(tmp_path: Path) -> None:
    path = tmp_path / "none.csv"
    with pytest.raises(InputError, match=rf"^{re.escape(str(path))}: cannot read"):
        read_motion_csv(path)
