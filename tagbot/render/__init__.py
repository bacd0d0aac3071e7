"""Pictures of tags: a brush swept along the motion, animations, and speed and action-plan plots.

The paper's §5, with an ink model: the ink laid grows with the time the pen spends (thin where it
is fast), spreads a little and drips where it pools (:mod:`.brush`; presets ``marker``,
``fineliner``, ``chisel``, ``spray``); the samples,
spaced by the model's speed, animate the gesture; Figures 4, 6 and 12 plot the speed with each
stroke's lognormal and the action plan. ::

    from tagbot.render import render, render_array, plot, pictures_for_run
    render(tag, "tag.png", drips=True, seed=1)     # or .svg, .gif, .mp4 (tagbot[video])
    render(tag, "spray.png", brush="spray", texture=True, seed=1)
    pixels = render_array(tag, size=(800, 600))    # RGBA uint8 (600, 800, 4)
    plot(tag, "speed.png", kind="speed")           # or kind="plan"
    pictures_for_run("runs/2024-...")              # tag.png, executed.png, execution.png,
                                                   # speed.png, plan.png

Submodules are imported on first use (matplotlib is not loaded by ``import tagbot.render``).
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "PRESETS": "brush",
    "Brush": "brush",
    "Drip": "brush",
    "Painting": "brush",
    "RenderError": "brush",
    "paint": "brush",
    "View": "raster",
    "make_view": "raster",
    "Rendered": "api",
    "prepare": "api",
    "render": "api",
    "render_array": "api",
    "Timing": "animate",
    "frame_times": "animate",
    "RunFolder": "plots",
    "load_run": "plots",
    "pictures_for_run": "plots",
    "plan_figure": "plots",
    "plot": "plots",
    "speed_curves": "plots",
    "speed_figure": "plots",
}

__all__ = [
    "PRESETS",
    "Brush",
    "Drip",
    "Painting",
    "RenderError",
    "Rendered",
    "RunFolder",
    "Timing",
    "View",
    "frame_times",
    "load_run",
    "make_view",
    "paint",
    "pictures_for_run",
    "plan_figure",
    "plot",
    "prepare",
    "render",
    "render_array",
    "speed_curves",
    "speed_figure",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'tagbot.render' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"tagbot.render.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
