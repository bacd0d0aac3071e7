"""``tagbot fit`` and ``tagbot vary`` from the command line."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from tagbot.cli import main
from tagbot.io.planfile import load_plan

ROOT = Path(__file__).resolve().parents[2]
CAE = ROOT / "tagbot" / "examples" / "cae.json"


def run(capsys, *args):
    code = main([os.fspath(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str, fragment: str) -> None:
    assert err.startswith("tagbot: error: ") and err.count("\n") == 1, err
    assert fragment in err, err


@pytest.fixture
def points_csv(tmp_path: Path) -> Path:
    """Two traces as a point CSV (a pen column splits them), with timing."""
    t = np.linspace(0, 1, 120)
    rows = ["t,x,y,pen"]
    rows += [f"{ti:.4f},{60 * ti:.4f},{10 * np.sin(5 * ti):.4f},1" for ti in t]
    rows += ["1.3,0,30,0"]
    rows += [f"{1.5 + ti:.4f},{40 * ti:.4f},{30 + 15 * ti**2:.4f},1" for ti in t]
    path = tmp_path / "points.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


def test_fit_writes_a_plan_and_reports(capsys, points_csv, tmp_path):
    out_path = tmp_path / "plan.json"
    code, out, err = run(capsys, "fit", points_csv, "-o", out_path)
    assert code == 0 and out == ""
    assert "2 traces (240 points)" in err and "strokes" in err and "shape error mean" in err
    assert "velocity SNR" in err and "fit " in err
    tag = load_plan(out_path)
    assert len(tag.plans) == 2 and tag.model == "gamma"


def test_fit_to_stdout_and_sigma_model(capsys, points_csv):
    code, out, _ = run(capsys, "fit", points_csv, "--model", "sigma", "--no-refine")
    assert code == 0
    document = json.loads(out)
    assert document["model"] == "sigma"
    assert all("phi" in s for p in document["plans"] for s in p["strokes"])


def test_fit_bad_input_is_one_line(capsys, tmp_path):
    garbage = tmp_path / "tag.gml"
    garbage.write_bytes(b"%PDF-1.4 not a tag")
    code, _, err = run(capsys, "fit", garbage)
    assert code == 2
    one_line_error(err, "tag.gml")
    code, _, err = run(capsys, "fit", tmp_path / "missing.gml")
    assert code == 2
    one_line_error(err, "missing.gml")


def test_vary_prints_a_generated_seed_and_repeats_with_it(capsys, tmp_path):
    code, _, err = run(capsys, "vary", CAE, "--count", "3", "-o", tmp_path / "a")
    assert code == 0
    seed = int(err.split()[1])
    assert f"--seed {seed}" in err
    files = sorted((tmp_path / "a").iterdir())
    assert [f.name for f in files] == ["cae-1.json", "cae-2.json", "cae-3.json"]
    code, _, err = run(capsys, "vary", CAE, "-n", "3", "--seed", str(seed), "-o", tmp_path / "b")
    assert code == 0 and "seed" not in err.split("\n")[0]
    for f in files:
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes()


@pytest.mark.parametrize("args", [["--count", "0"], ["--count", "x"], ["--seed", "-3", "-n", "2"]])
def test_vary_bad_arguments(capsys, tmp_path, args):
    code, _, err = run(capsys, "vary", CAE, *args, "-o", tmp_path)
    assert code == 2
    one_line_error(err, "")


@pytest.mark.parametrize("command", ["fit", "vary"])
def test_help(capsys, command):
    code, out, _ = run(capsys, command, "--help")
    assert code == 0 and out.startswith(f"Usage: tagbot {command}")
