"""The numeric core: lognormal profiles, arcs and Euler spirals, ΣΛ*/ΓΛ* plans, sampling.

Pure numpy/scipy, no I/O.
"""

from tagbot.model.euler import Clothoids, fit_euler
from tagbot.model.lognormal import (
    CharacteristicTimes,
    characteristic_times,
    lognormal,
    lognormal_cdf,
    lognormal_time,
)
from tagbot.model.motion import Motion, evaluate_plan, sample
from tagbot.model.plan import (
    DEFAULT_MU,
    DEFAULT_SIGMA,
    END_TOLERANCE,
    MODELS,
    Model,
    Plan,
    Tag,
    random_plan,
    random_timed_plan,
    sequence,
)

__all__ = [
    "DEFAULT_MU",
    "DEFAULT_SIGMA",
    "END_TOLERANCE",
    "MODELS",
    "CharacteristicTimes",
    "Clothoids",
    "Model",
    "Motion",
    "Plan",
    "Tag",
    "characteristic_times",
    "evaluate_plan",
    "fit_euler",
    "lognormal",
    "lognormal_cdf",
    "lognormal_time",
    "random_plan",
    "random_timed_plan",
    "sample",
    "sequence",
]
