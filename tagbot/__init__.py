"""tagbot: graffiti tags as the motion of an expert hand, for screens, pen plotters and servo arms.

The public API::

    import tagbot
    tag = tagbot.load_plan("tag.json")        # a Tag: ΓΛ*/ΣΛ* plans with pen lifts between them
    motion = tag.sample(0.01)                 # Motion: t, xy, v, speed, pen at a 10 ms step
    tagbot.save_plan(tag, "copy.json")
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from tagbot.errors import InputError, PlanError, PlanFileError, TagbotError
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
    "InputError",
    "Motion",
    "Plan",
    "PlanError",
    "PlanFileError",
    "Tag",
    "TagbotError",
    "__version__",
    "fit_euler",
    "load_plan",
    "lognormal",
    "lognormal_cdf",
    "save_plan",
]
