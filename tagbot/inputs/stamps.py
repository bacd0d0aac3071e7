"""Sampling instants from recorded time stamps.

A digitiser's time stamps can be off from the instants its samples were taken at: events
delivered in bursts, stamped by the display frame that read them (16 ms apart at 60 Hz), late by
a varying delay. Then the displacement between two samples follows the sampling, not the
stamps, and velocities taken from the stamps swing by tens of per cent from one sample to the
next (development GML: intervals of 16, 32 and 48 ms holding about equal displacements). Other
captures are stamped exactly but sampled irregularly (a mouse reports when it moves).

:func:`sample_instants` decides from the data which holds, per trace:

1. Repeated stamps are spread evenly towards the next one (:func:`spread_stamps`).
2. A clock whose intervals all lie within :data:`REGULAR` of their median is taken as it is.
3. Otherwise the stamps are regressed on the sample number (:func:`regular_instants`: locally
   linear, a Gaussian :data:`SMOOTHING` samples wide, in segments split where an interval
   exceeds :data:`GAP` median intervals: a pause or dropped samples stays as recorded), the
   instants a steady sampler would have had.
4. The trace's instants are the blend ``(1 − a)·stamps + a·regular`` for the ``a`` of
   :data:`BLENDS` under which the velocity by sample differences is smoothest
   (:func:`roughness`): stamps that carry the timing keep it, stamps that carry noise lose it.

On synthetic captures (``tests/inputs/test_stamps.py``) the instants come out 4.6-4.8 times
closer to the true ones (median) for a 30 Hz sampler stamped by the 16 ms frame that read it and
for a 60 Hz one whose events arrive 0-8 ms late, and exact stamps, of steady or irregular
sampling, are kept as they are. The timed fit (:mod:`tagbot.gesture.timing`) and the recorded
velocity of the SNR (:func:`tagbot.metrics.recorded_velocity`) both work on these instants.
Compiled (:mod:`tagbot.inputs.stamps_kernels`), linear in the samples.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tagbot.inputs import stamps_kernels

Array = NDArray[np.float64]

SMOOTHING = 6.0
"""Width (standard deviation) of the stamps' regression on the sample number, in samples (3 and 6
score alike on the synthetic captures; 6 scored 0.3 dB higher on the development GML)."""
GAP = 2.5
"""An interval longer than this many median intervals ends a segment of steady sampling."""
REGULAR = 0.01
"""A clock whose positive intervals are all within this fraction of their median is steady."""
BLENDS = (0.0, 0.25, 0.5, 0.75, 1.0)
"""Candidate weights of the regular instants against the stamps."""

__all__ = [
    "BLENDS",
    "GAP",
    "REGULAR",
    "SMOOTHING",
    "regular_instants",
    "roughness",
    "sample_instants",
    "spread_stamps",
]


def _kernel_array(a: ArrayLike) -> Array:
    return np.ascontiguousarray(a, dtype=np.float64)


def spread_stamps(t: ArrayLike) -> Array:
    """Time stamps with each run of equal (or out-of-order) stamps spread evenly over the
    interval to the next distinct stamp, at most one median sampling interval apart."""
    return stamps_kernels.spread(_kernel_array(t))


def regular_instants(t: ArrayLike, width: float = SMOOTHING, gap: float = GAP) -> Array:
    """The instants of a steady sampler behind increasing stamps ``t``: per segment between
    intervals longer than ``gap`` median intervals, a Gaussian-weighted (``width`` samples)
    local-linear regression of the stamps on the sample number. Exact on a steady clock."""
    return stamps_kernels.regular(_kernel_array(t), width, gap)


def roughness(t: ArrayLike, xy: ArrayLike) -> float:
    """How much the velocity by sample differences (under instants ``t``) changes from one
    interval to the next, relative to its energy: ``Σ|Δv|² / Σ|v|²``."""
    return float(stamps_kernels.roughness(_kernel_array(t), _kernel_array(xy)))


def sample_instants(t: ArrayLike, xy: ArrayLike) -> tuple[Array, float]:
    """The instants at which samples ``xy`` stamped ``t`` were most likely taken, and the weight
    given to a steady sampler's instants (0: the stamps as recorded; see the module doc)."""
    instants, blend = stamps_kernels.sample_instants(
        _kernel_array(t), _kernel_array(xy), SMOOTHING, GAP, REGULAR, np.array(BLENDS)
    )
    return instants, float(blend)
