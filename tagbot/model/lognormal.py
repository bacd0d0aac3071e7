"""The lognormal speed profile Λ, its CDF W, and its characteristic times.

A stroke that starts at ``t0`` moves with speed ``D·Λ(t)`` (Plamondon's Kinematic Theory), with::

    Λ(t) = exp(-(ln(t - t0) - mu)² / (2 sigma²)) / (sigma √(2π) (t - t0))    for t > t0, else 0
    W(t) = ½ (1 + erf((ln(t - t0) - mu) / (sigma √2)))                      (the CDF, 0 → 1)

The paper's eq. 1 prints the exponent without its minus sign; this is the normalised density.
Every function here is vectorised over ``t`` and broadcasts over the parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import ndtr, ndtri

_SQRT_2PI = float(np.sqrt(2.0 * np.pi))


def _log_elapsed(t: ArrayLike, t0: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Return ``ln(t - t0)`` (``-inf`` where ``t <= t0``) and the mask ``t > t0``."""
    elapsed = np.asarray(t, dtype=float) - np.asarray(t0, dtype=float)
    active = elapsed > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        log_elapsed = np.where(active, np.log(np.where(active, elapsed, 1.0)), -np.inf)
    return log_elapsed, active


def lognormal(t: ArrayLike, t0: ArrayLike, mu: ArrayLike, sigma: ArrayLike) -> NDArray[np.float64]:
    """Λ(t): the lognormal speed profile of unit area (0 for ``t <= t0``)."""
    log_elapsed, active = _log_elapsed(t, t0)
    sigma = np.asarray(sigma, dtype=float)
    with np.errstate(invalid="ignore", over="ignore"):
        z = (log_elapsed - mu) / sigma
        value = np.exp(-0.5 * z * z - log_elapsed) / (sigma * _SQRT_2PI)
    return np.where(active, value, 0.0)


def lognormal_cdf(
    t: ArrayLike, t0: ArrayLike, mu: ArrayLike, sigma: ArrayLike
) -> NDArray[np.float64]:
    """W(t): the fraction of the stroke completed at ``t`` (0 for ``t <= t0``, → 1)."""
    log_elapsed, _ = _log_elapsed(t, t0)
    return ndtr((log_elapsed - mu) / np.asarray(sigma, dtype=float))


def lognormal_time(
    fraction: ArrayLike, t0: ArrayLike, mu: ArrayLike, sigma: ArrayLike
) -> NDArray[np.float64]:
    """The inverse of W: the time at which ``fraction`` (in (0, 1)) of the stroke is done."""
    return np.asarray(t0, dtype=float) + np.exp(
        mu + np.asarray(sigma, dtype=float) * ndtri(fraction)
    )


@dataclass(frozen=True)
class CharacteristicTimes:
    """Landmarks of a lognormal profile, in seconds on the same clock as ``t0``."""

    onset: float
    """t0: the command time; Λ is zero before it."""
    peak: float
    """The mode of Λ: ``t0 + exp(mu - sigma²)``."""
    median: float
    """Half the stroke is done: ``t0 + exp(mu)``."""
    start: float
    """Practical start: W reaches ``eps``."""
    end: float
    """Practical end: 1 - W falls to ``eps``."""


def characteristic_times(
    t0: float, mu: float, sigma: float, eps: float = 1e-6
) -> CharacteristicTimes:
    """Onset, peak, median, and the practical start and end where W is within ``eps`` of 0 and 1."""
    if not 0.0 < eps < 0.5:
        raise ValueError(f"eps: must be in (0, 0.5), got {eps!r}")
    z = -float(ndtri(eps))
    return CharacteristicTimes(
        onset=float(t0),
        peak=float(t0 + np.exp(mu - sigma * sigma)),
        median=float(t0 + np.exp(mu)),
        start=float(t0 + np.exp(mu - sigma * z)),
        end=float(t0 + np.exp(mu + sigma * z)),
    )
