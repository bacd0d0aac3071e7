"""tagbot: graffiti tags as the motion of an expert hand, for screens, pen plotters and servo arms.

The public API::

    import tagbot
    traces = tagbot.load_traces("tag.gml")    # GML, #000000book JSON, SVG or point files
    tag = tagbot.fit(traces)                  # a Tag: ΓΛ*/ΣΛ* plans with pen lifts between them
    motion = tag.sample(0.01)                 # Motion: t, xy, v, speed, pen at a 10 ms step
    tagbot.save_plan(tag, "tag.json")
    variants = tagbot.vary(tag, 10, seed=1)   # plausible instances of the same tag
"""

from __future__ import annotations

import importlib
import os
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version
from typing import TYPE_CHECKING

from tagbot._lazy import lazy_exports
from tagbot.errors import InputError, PlanError, PlanFileError, TagbotError

try:
    __version__ = _version("tagbot")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "unknown"

if TYPE_CHECKING:
    from tagbot.gesture import FitOptions, Variation, fit, vary
    from tagbot.inputs import Trace, load_traces
    from tagbot.io.planfile import load_plan, save_plan
    from tagbot.model import (
        DEFAULT_MU,
        DEFAULT_SIGMA,
        Clothoids,
        Motion,
        Plan,
        Tag,
        fit_euler,
        lognormal,
        lognormal_cdf,
    )

# The numeric core (numpy, scipy, numba) loads on first use of a name below, so that
# ``import tagbot`` and ``tagbot --help`` stay fast.
_LAZY = {
    "FitOptions": "tagbot.gesture",
    "Variation": "tagbot.gesture",
    "fit": "tagbot.gesture",
    "vary": "tagbot.gesture",
    "Trace": "tagbot.inputs",
    "load_traces": "tagbot.inputs",
    "load_plan": "tagbot.io.planfile",
    "save_plan": "tagbot.io.planfile",
    "DEFAULT_MU": "tagbot.model",
    "DEFAULT_SIGMA": "tagbot.model",
    "Clothoids": "tagbot.model",
    "Motion": "tagbot.model",
    "Plan": "tagbot.model",
    "Tag": "tagbot.model",
    "fit_euler": "tagbot.model",
    "lognormal": "tagbot.model",
    "lognormal_cdf": "tagbot.model",
}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY)

if os.environ.get("TAGBOT_CHECK_KERNELS", "") not in ("", "0"):
    importlib.import_module("tagbot.kernel_check")  # checks every compiled kernel's arguments

__all__ = [
    "DEFAULT_MU",
    "DEFAULT_SIGMA",
    "Clothoids",
    "FitOptions",
    "InputError",
    "Motion",
    "Plan",
    "PlanError",
    "PlanFileError",
    "Tag",
    "TagbotError",
    "Trace",
    "Variation",
    "__version__",
    "fit",
    "fit_euler",
    "load_plan",
    "load_traces",
    "lognormal",
    "lognormal_cdf",
    "save_plan",
    "vary",
]
