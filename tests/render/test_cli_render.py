"""`tagbot render` and `tagbot plot`: outputs, seeds, exit codes and one-line errors."""

from __future__ import annotations

import importlib.util
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from PIL import Image

from tagbot.cli import main
from tagbot.io.motionfile import write_motion_csv
from tagbot.model import Tag
from tests.render.conftest import EXAMPLES

CAE = EXAMPLES / "cae.json"
LETTER_B = EXAMPLES / "letter-b.json"


def run(capsys: pytest.CaptureFixture[str], *args: str | os.PathLike[str]) -> tuple[int, str, str]:
    code = main([os.fspath(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err: str, *fragments: str) -> None:
    assert err.startswith("tagbot: error: "), err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    for fragment in fragments:
        assert fragment in err, (fragment, err)


def test_render_png(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "cae.png"
    code, stdout, err = run(capsys, "render", CAE, "-o", out, "--size", "300x200", "--dpi", "150")
    assert (code, stdout) == (0, "")
    assert err == f"wrote {out}: 300x200 PNG\n"
    with Image.open(out) as image:
        assert image.size == (300, 200)


def test_render_prints_the_seed_it_draws(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out = tmp_path / "cae.png"
    code, _, err = run(capsys, "render", CAE, "-o", out, "--size", "200", "--drips", "--texture")
    assert code == 0
    seed = re.match(r"seed (\d+) \(pass --seed \1 to repeat\)\n", err)
    assert seed, err
    again = tmp_path / "again.png"
    code, _, err = run(
        capsys,
        "render",
        CAE,
        "-o",
        again,
        "--size",
        "200",
        "--drips",
        "--texture",
        "--seed",
        seed[1],
    )
    assert code == 0 and not err.startswith("seed")
    assert out.read_bytes() == again.read_bytes()


def test_render_svg_and_gif(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _, err = run(
        capsys, "render", LETTER_B, "-o", tmp_path / "b.svg", "--seed", "1", "--drips"
    )
    assert code == 0
    # The SVG is in mm, and the message says so.
    root = ET.parse(tmp_path / "b.svg").getroot()
    width, height = root.get("width"), root.get("height")
    assert width.endswith("mm") and height.endswith("mm")
    size = f"{float(width[:-2]):.1f}x{float(height[:-2]):.1f} mm SVG"
    assert size in err, err
    gif = tmp_path / "b.gif"
    code, _, err = run(
        capsys,
        "render",
        LETTER_B,
        "-o",
        gif,
        "--size",
        "80",
        "--fps",
        "10",
        "--speed",
        "2",
        "--hold",
        "0",
    )
    assert code == 0
    reported = re.search(r"(\d+)x(\d+) GIF, (\d+) frames, 1\.10 s", err)
    assert reported, err
    with Image.open(gif) as image:
        assert image.format == "GIF"
        assert (image.width, image.height, image.n_frames) == tuple(map(int, reported.groups()))


def test_render_fits_an_input_trace(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    from tagbot.io.planfile import load_plan

    motion = load_plan(LETTER_B).sample(0.01)
    trace = tmp_path / "trace.csv"
    write_motion_csv(motion, trace)
    for model in ("gamma", "sigma"):
        code, _, err = run(
            capsys,
            "render",
            trace,
            "-o",
            tmp_path / f"{model}.png",
            "--model",
            model,
            "--size",
            "100",
        )
        assert code == 0, err


def test_render_errors(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    code, _, err = run(capsys, "render", CAE, "-o", tmp_path / "cae.jpg")
    assert code == 2
    assert_one_line_error(err, "unknown picture format", ".png, .svg, .gif or .mp4")
    code, _, err = run(capsys, "render", CAE, "-o", tmp_path / "x.png", "--size", "axb")
    assert code == 2
    assert_one_line_error(err, "--size")
    code, _, err = run(capsys, "render", tmp_path / "missing.json", "-o", tmp_path / "x.png")
    assert code == 2
    assert_one_line_error(err, "missing.json")
    junk = tmp_path / "junk.json"
    junk.write_text(
        '{"format": "tagbot-plan", "version": 1, "model": "gamma", "units": "mm", "plans": 0}'
    )
    code, _, err = run(capsys, "render", junk, "-o", tmp_path / "x.png")
    assert code == 2
    assert_one_line_error(err, "plans")
    code, _, err = run(capsys, "render", CAE, "-o", tmp_path / "x.png", "--color", "octarine")
    assert code == 2
    assert_one_line_error(err, "color: not a colour")

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name == "imageio_ffmpeg" else real(name, *a),
    )
    code, _, err = run(capsys, "render", CAE, "-o", tmp_path / "cae.mp4")
    assert code == 2
    assert_one_line_error(err, "imageio-ffmpeg", "tagbot[video]")
    assert not (tmp_path / "cae.mp4").exists()


@pytest.mark.parametrize("kind", ["speed", "plan"])
def test_plot_plan_file(capsys: pytest.CaptureFixture[str], tmp_path: Path, kind: str) -> None:
    out = tmp_path / f"{kind}.png"
    code, _, err = run(capsys, "plot", CAE, "-o", out, "--kind", kind)
    assert (code, err) == (0, f"wrote {out}\n")
    assert out.stat().st_size > 1000


def test_plot_run_folder(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, run_dir: Path, cae: Tag
) -> None:
    out = tmp_path / "speed.svg"
    code, _, err = run(capsys, "plot", run_dir, "-o", out)
    assert code == 0, err
    assert out.read_text().lstrip().startswith("<?xml")
    code, _, err = run(capsys, "plot", run_dir, "-o", tmp_path / "plan.png", "--kind", "plan")
    assert code == 0, err


def test_plot_errors(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _, err = run(capsys, "plot", CAE, "-o", tmp_path / "x.gif")
    assert code == 2
    assert_one_line_error(err, "a plot is a .png, .svg or .pdf")
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = run(capsys, "plot", empty, "-o", tmp_path / "x.png")
    assert code == 2
    assert_one_line_error(err, "not a run folder")
    code, _, err = run(capsys, "plot", CAE, "-o", tmp_path / "x.png", "--kind", "colour")
    assert code == 2
    assert_one_line_error(err, "--kind")
    code, _, err = run(capsys, "plot", CAE, "-o", tmp_path / "x.png", "--model", "sigma")
    assert code == 0
    assert err.startswith("note: --model applies to traces")


def test_help_lists_the_commands(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(capsys, "--help")
    assert code == 0
    assert "render" in out and "plot" in out
    for command in ("render", "plot"):
        code, out, _ = run(capsys, command, "--help")
        assert code == 0 and out.startswith(f"Usage: tagbot {command}")
