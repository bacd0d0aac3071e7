"""Reconstruction of plans from traces (paper §6) and variations of a plan (paper §7)."""

from tagbot.gesture.reconstruct import (
    FitOptions,
    Reconstruction,
    critical_points,
    fit,
    fit_trace,
    reconstruction,
)
from tagbot.gesture.vary import Variation, iter_vary, new_seed, vary

__all__ = [
    "FitOptions",
    "Reconstruction",
    "Variation",
    "critical_points",
    "fit",
    "fit_trace",
    "iter_vary",
    "new_seed",
    "reconstruction",
    "vary",
]
