"""Reconstruction of plans from traces (paper §6) and variations of a plan (paper §7)."""

from tagbot.fit.reconstruct import FitOptions, critical_points, fit, fit_trace

__all__ = ["FitOptions", "critical_points", "fit", "fit_trace"]
