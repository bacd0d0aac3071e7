"""The plan file as bytes, and the one-line messages that name what is wrong (issue 34)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tagbot.errors import PlanFileError
from tagbot.io.planfile import json_kind, load_plan, plan_bytes, save_plan, tag_from_dict

GAMMA = """\
{
  "format": "tagbot-plan",
  "version": 2,
  "model": "gamma",
  "units": "mm",
  "plans": [
    {
      "start": 0.0,
      "ink": [0.05, 0.5],
      "targets": [
        [0.0, 0.0],
        [10.0, 5.0],
        [20.0, 0.0]
      ],
      "strokes": [
        {"dt": 0.0, "mu": -1.5, "sigma": 0.25, "phi1": 0.5, "phi2": 0.125},
        {"dt": 0.25, "mu": -0.3333333333333333, "sigma": 0.1, "phi1": -0.25, "phi2": 0.75}
      ]
    },
    {
      "start": 2.0,
      "targets": [
        [30.0, 0.0],
        [40.0, 2.5]
      ],
      "strokes": [
        {"dt": 0.0, "mu": -1.0, "sigma": 0.3, "phi1": -0.2, "phi2": 0.2}
      ]
    }
  ]
}
"""

SIGMA = """\
{
  "format": "tagbot-plan",
  "version": 1,
  "model": "sigma",
  "units": "px",
  "plans": [
    {
      "start": 2.0,
      "targets": [
        [30.0, 0.0],
        [40.0, 2.5]
      ],
      "strokes": [
        {"dt": 0.0, "mu": -1.0, "sigma": 0.3, "phi": 0.2}
      ]
    }
  ]
}
"""


SIGMA_INK = SIGMA.replace('"version": 1', '"version": 2').replace(
    '"start": 2.0,', '"start": 2.0,\n      "ink": [0.0625, 0.25],'
)
"""The ΣΛ file with an ink window (the pen touches down and lifts off moving): version 2."""


@pytest.mark.parametrize("text", [GAMMA, SIGMA, SIGMA_INK], ids=["gamma-ink", "sigma", "sigma-ink"])
def test_a_plan_file_loads_and_saves_back_byte_for_byte(text: str, tmp_path: Path) -> None:
    source = tmp_path / "in.json"
    source.write_text(text, encoding="utf-8")
    tag = load_plan(source)
    assert plan_bytes(tag) == text.encode("utf-8")
    out = tmp_path / "out.json"
    save_plan(tag, out)
    assert out.read_bytes() == text.encode("utf-8")


def test_a_loaded_plan_holds_the_files_numbers_exactly(tmp_path: Path) -> None:
    (tmp_path / "g.json").write_text(GAMMA, encoding="utf-8")
    tag = load_plan(tmp_path / "g.json")
    assert (tag.model, tag.units, len(tag.plans)) == ("gamma", "mm", 2)
    first, second = tag.plans
    assert first.start == 0.0 and first.ink == (0.05, 0.5) and second.ink is None
    np.testing.assert_array_equal(first.targets, [[0, 0], [10, 5], [20, 0]])
    assert first.dt.tolist() == [0.0, 0.25] and first.mu.tolist() == [-1.5, -1 / 3]
    assert first.sigma.tolist() == [0.25, 0.1]
    assert first.phi1.tolist() == [0.5, -0.25] and first.phi2.tolist() == [0.125, 0.75]
    assert second.start == 2.0 and second.phi1.tolist() == [-0.2]
    (tmp_path / "s.json").write_text(SIGMA, encoding="utf-8")
    (plan,) = load_plan(tmp_path / "s.json").plans
    assert plan.phi1.tolist() == [-0.2] and plan.phi2.tolist() == [0.2]


@pytest.mark.parametrize(
    ("value", "kind"),
    [
        (None, "null"),
        (True, "a boolean"),
        (3, "a number"),
        (2.5, "a number"),
        ("x", "a string"),
        ([1], "a list"),
    ],
)
def test_the_top_level_names_what_it_got(value: Any, kind: str) -> None:
    with pytest.raises(PlanFileError) as e:
        tag_from_dict(value)
    assert str(e.value) == f"expected a JSON object at the top level, got {kind}"


def test_json_kind_quotes_numbers_when_asked() -> None:
    assert json_kind(2.5, quote_numbers=True) == "2.5" and json_kind(3, True) == "3"
    assert json_kind(True, quote_numbers=True) == "a boolean"
    assert json_kind({"a": 1}) == "an object"
    assert json_kind(b"x") == "bytes"  # not JSON: its Python type


def _doc() -> dict[str, Any]:
    return json.loads(GAMMA)


def _message(d: Any) -> str:
    with pytest.raises(PlanFileError) as e:
        tag_from_dict(d)
    return str(e.value)


def test_a_long_value_is_shown_cut_to_40_characters() -> None:
    d = _doc()
    d["version"] = "v" * 60
    shown = '"' + "v" * 36 + "..."  # 37 characters of the JSON text, then an ellipsis
    assert _message(d) == f"version: unsupported {shown} (this tagbot reads 1 and 2)"
    d["version"] = "v" * 38  # 40 characters quoted: shown whole
    assert _message(d) == f'version: unsupported "{"v" * 38}" (this tagbot reads 1 and 2)'


def test_a_value_is_shown_in_ascii_on_one_line() -> None:
    """A shown string's non-ASCII characters are escaped, a line separator among them, so the
    message stays one ASCII line."""
    d = _doc()
    d["model"] = "sigma\u2028gamma \u00e4"
    message = _message(d)
    assert message == 'model: unknown "sigma\\u2028gamma \\u00e4" (expected "gamma" or "sigma")'
    assert message.isascii() and len(message.splitlines()) == 1


def test_a_value_json_cannot_write_is_shown_as_python_writes_it() -> None:
    """tag_from_dict takes any mapping: a value no JSON text holds (bytes) is still shown."""
    d = _doc()
    d["format"] = b"tagbot-plan"
    assert _message(d) == "format: expected \"tagbot-plan\", got b'tagbot-plan'"


@pytest.mark.parametrize(
    ("point", "message"),
    [
        ([1.0, 2.0, 3.0], "expected [x, y] numbers, got [1.0, 2.0, 3.0]"),
        ([1.0], "expected [x, y] numbers, got [1.0]"),
        ([True, 1.0], "expected [x, y] numbers, got [true, 1.0]"),
        ({"x": 1}, 'expected [x, y] numbers, got {"x": 1}'),
        ([float("inf"), 0.0], "must be finite, got [Infinity, 0.0]"),
        ([0.0, 10**400], "must be finite, got [0.0, 1000000000000000000000000000000..."),
    ],
)
def test_a_bad_target_is_named_with_what_it_holds(point: Any, message: str) -> None:
    d = _doc()
    d["plans"][1]["targets"][1] = point
    assert _message(d) == f"plans[1].targets[1]: {message}"


def test_a_stroke_number_is_checked_where_it_is() -> None:
    d = _doc()
    d["plans"][0]["strokes"][1]["sigma"] = "0.1"
    assert _message(d) == 'plans[0].strokes[1].sigma: expected a number, got "0.1"'
    d = _doc()
    d["plans"][0]["strokes"][1]["phi2"] = 10**400
    assert _message(d).startswith("plans[0].strokes[1].phi2: must be finite, got 1000")
    d = _doc()
    del d["plans"][1]["strokes"]
    assert _message(d) == "plans[1].strokes: missing"


def test_a_sigma_plans_ink_window_is_kept(tmp_path: Path) -> None:
    """A ΣΛ plan's ink window is read as it is written, like a gamma plan's."""
    path = tmp_path / "sigma_ink.json"
    path.write_text(SIGMA_INK, encoding="utf-8")
    (plan,) = load_plan(path).plans
    assert plan.ink == (0.0625, 0.25) and plan.start == 2.0
    assert np.array_equal(plan.phi1, -plan.phi2) and plan.phi2.tolist() == [0.2]
