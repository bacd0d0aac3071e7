"""tagbot: graffiti tags as the motion of an expert hand, for screens, pen plotters and servo arms.

The public API::

    import tagbot
    traces = tagbot.load_traces("tag.gml")    # GML, #000000book JSON, SVG or point files
    tag = tagbot.fit(traces)                  # a Tag: ΓΛ*/ΣΛ* plans with pen lifts between them
    motion = tag.sample(0.01)                 # Motion: t, xy, v, speed, pen at a 10 ms step
    tagbot.save_plan(tag, "tag.json")
    variants = tagbot.vary(tag, 10, seed=1)   # plausible instances of the same tag
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from tagbot.errors import InputError, PlanError, PlanFileError, TagbotError
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

try:
    __version__ = _version("tagbot")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "unknown"

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
