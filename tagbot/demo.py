"""``tagbot demo``: the whole pipeline on a tag the project ships, into one folder.

1. **fit**: the real DustTag capture ``examples/hello-world-147.json`` ("hello world" written on a
   phone, with timing) becomes a ΓΛ* plan (``plan.json``), with its shape error and velocity SNR;
2. **plots**: the action plan over the trace (``plan.png``) and the speed with each stroke's
   lognormal and the recorded speed (``speed.png``);
3. **variations**: plausible instances (``variations/*.json``) and a contact sheet
   (``variations.png``, the original large and marked);
4. **render**: the tag painted in marker ink that spreads and drips where the pen lingers
   (``tag.png`` textured, ``tag.svg``) and drawn progressively with its drips (``tag.gif``);
5. **plotter**: drawn on the simulated Grbl plotter (run folder ``plotter/``, with the pictures
   of what the plan asked for and what the machine drew);
6. **arm**: drawn by the simulated DYNAMIXEL arm (run folder ``arm/``, the same pictures);
7. **openmanipulator-x**: drawn by ROBOTIS's OpenManipulator-X in the physics simulator (run
   folder ``openmanipulator-x/``: where the nib touched the paper);

then ``summary.json`` and a short summary of where everything is. Nothing touches hardware.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["DEMO_INPUT", "DemoResult", "run_demo"]

DEMO_INPUT = "hello-world-147.json"
"""The shipped capture the demo starts from (public domain, see examples/README.md)."""

STEPS = ("fit", "plots", "variations", "render", "plotter", "arm", "openmanipulator-x")

MACHINES = (
    ("plotter", "grbl", None),
    ("arm", "dynamixel", None),
    ("openmanipulator-x", "dynamixel", "openmanipulator-x"),
)
"""Demo steps drawing on a machine: step name (and run folder), device, profile."""


@dataclass
class DemoResult:
    """Where the demo put things, and the headline figures."""

    folder: Path
    files: dict[str, str] = field(default_factory=dict)
    figures: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)

    def summary(self) -> str:
        f = self.figures
        w = max(len(step) for step in STEPS)  # every step's label in one column
        lines = [f"demo folder: {self.folder}"]
        lines.append(
            f"  {'fit':<{w}} {f['strokes']} strokes in {f['plans']} plans, shape error "
            f"{100 * f['shape_error_mean']:.2f} % mean of the size -> {self.files['plan']}"
        )
        lines.append(f"  {'plots':<{w}} {self.files['plan_plot']}, {self.files['speed_plot']}")
        lines.append(
            f"  {'variations':<{w}} {f['variations']} plans (seed {f['seed']}) -> "
            f"{self.files['variations_sheet']}"
        )
        files = self.files
        lines.append(f"  {'render':<{w}} {files['png']}, {files['svg']}, {files['gif']}")
        for device, _, _ in MACHINES:
            r = f[device]
            lines.append(
                f"  {device:<{w}} run folder {self.files[device]}: path deviation "
                f"{r['path_deviation_mean_mm']:.3f} mm mean / {r['path_deviation_max_mm']:.3f} "
                f"mm max, speed SNR {r['speed_snr_db']:.1f} dB"
            )
        return "\n".join(lines)


def run_demo(
    out: str | Path,
    *,
    seed: int = 7,
    variations: int = 6,
    progress: Callable[[str, int, int], None] | None = None,
) -> DemoResult:
    """Run every step into ``out`` (created); ``progress(step, index, count)`` before each."""
    from tagbot.draw import draw
    from tagbot.gesture import fit, vary
    from tagbot.inputs import read_traces_bytes
    from tagbot.io.planfile import save_plan
    from tagbot.metrics import fit_report
    from tagbot.render import plot, render

    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    result = DemoResult(folder)

    def step(name: str) -> None:
        if progress is not None:
            progress(name, STEPS.index(name) + 1, len(STEPS))

    def timed(name: str, started: float) -> None:
        result.seconds[name] = round(time.perf_counter() - started, 3)

    started = time.perf_counter()
    step("fit")
    data = (resources.files("tagbot") / "examples" / DEMO_INPUT).read_bytes()
    traces = read_traces_bytes(data, DEMO_INPUT)
    tag = fit(traces)
    report = fit_report(traces, tag)
    save_plan(tag, folder / "plan.json")
    result.files["plan"] = "plan.json"
    result.figures.update(
        plans=len(tag.plans),
        strokes=report.strokes,
        shape_error_mean=report.shape.mean,
        shape_error_max=report.shape.max,
        velocity_snr_db=report.velocity_snr_db,
    )
    timed("fit", started)

    started = time.perf_counter()
    step("plots")
    plot(tag, folder / "plan.png", kind="plan", traces=traces)
    plot(tag, folder / "speed.png", kind="speed", traces=traces)
    result.files.update(plan_plot="plan.png", speed_plot="speed.png")
    timed("plots", started)

    started = time.perf_counter()
    step("variations")
    instances = vary(tag, variations, seed)
    (folder / "variations").mkdir(exist_ok=True)
    for i, instance in enumerate(instances, start=1):
        save_plan(instance, folder / "variations" / f"variation-{i}.json")
    _contact_sheet([tag, *instances], folder / "variations.png", seed)
    result.files["variations_sheet"] = "variations.png"
    result.figures.update(variations=variations, seed=seed)
    timed("variations", started)

    started = time.perf_counter()
    step("render")
    render(tag, folder / "tag.png", drips=True, seed=seed, texture=True, size=1600)
    render(tag, folder / "tag.svg", drips=True, seed=seed)
    render(tag, folder / "tag.gif", drips=True, seed=seed, texture=True, size=720, fps=20)
    result.files.update(png="tag.png", svg="tag.svg", gif="tag.gif")
    timed("render", started)

    for name, device, profile in MACHINES:
        started = time.perf_counter()
        step(name)
        run = draw(tag, folder / name, device=device, profile=profile)
        keys = ("path_deviation_mean_mm", "path_deviation_max_mm", "speed_snr_db")
        result.figures[name] = {k: run.report.get(k) for k in keys}
        result.files[name] = f"{name}/"
        timed(name, started)

    summary = {"files": result.files, "figures": result.figures, "seconds": result.seconds}
    (folder / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return result


def _contact_sheet(tags: list[Any], path: Path, seed: int, cell: int = 360) -> None:
    """The original (first, twice the size, marked) beside its variations, on a common scale,
    as one PNG with no empty slot: the variations fill ``rows`` rows beside an original
    ``rows`` cells high."""
    from PIL import Image, ImageDraw

    from tagbot.render import prepare, render_array

    seeds = [seed + i for i in range(len(tags))]
    boxes = np.array(
        [prepare(t, drips=True, seed=s).bounds() for t, s in zip(tags, seeds, strict=True)]
    )
    bounds = (*boxes[:, :2].min(axis=0), *boxes[:, 2:].max(axis=0))
    aspect = float(np.clip((bounds[2] - bounds[0]) / (bounds[3] - bounds[1]), 0.5, 2.0))
    cw, ch = round(cell * aspect), cell
    variations = len(tags) - 1
    rows = 2 if variations % 2 == 0 and variations >= 4 else 1
    columns = -(-variations // rows)
    big = (rows * cw, rows * ch)
    sheet = Image.new("RGB", (big[0] + columns * cw, big[1]), "white")
    original = render_array(tags[0], size=big, bounds=bounds, drips=True, seed=seeds[0])
    sheet.paste(Image.fromarray(original).convert("RGB"), (0, 0))
    for i, tag in enumerate(tags[1:]):
        pixels = render_array(tag, size=(cw, ch), bounds=bounds, drips=True, seed=seeds[i + 1])
        sheet.paste(
            Image.fromarray(pixels).convert("RGB"),
            (big[0] + (i % columns) * cw, (i // columns) * ch),
        )
    pen = ImageDraw.Draw(sheet)
    pen.rectangle((1, 1, big[0] - 2, big[1] - 2), outline="#c62828", width=3)
    pen.text((12, 10), "original", fill="#c62828", font_size=max(14, cell // 14))
    for i in range(variations):
        x, y = big[0] + (i % columns) * cw, (i // columns) * ch
        pen.rectangle((x, y, x + cw - 1, y + ch - 1), outline="#d0d0d0", width=1)
        pen.text(
            (x + 10, y + 8), f"variation {i + 1}", fill="#707070", font_size=max(12, cell // 18)
        )
    sheet.save(path)
