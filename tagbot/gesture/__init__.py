"""Reconstruction of plans from traces (paper §6) and variations of a plan (paper §7)."""

from tagbot.gesture.reconstruct import FitOptions, critical_points, fit, fit_trace
from tagbot.gesture.vary import Variation, iter_vary, new_seed, vary

__all__ = [
    "FitOptions",
    "Variation",
    "critical_points",
    "fit",
    "fit_trace",
    "iter_vary",
    "new_seed",
    "vary",
]
