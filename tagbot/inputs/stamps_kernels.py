"""Compiled loops of :mod:`tagbot.inputs.stamps` (numba): linear in the samples."""

from __future__ import annotations

import math

import numpy as np

from tagbot.model.kernels import compiled

TIE = 1e-9
"""Roughnesses within this fraction of each other are equal (rounding decides nothing)."""


@compiled
def spread(t: np.ndarray) -> np.ndarray:
    """:func:`tagbot.inputs.stamps.spread_stamps` (``t`` made non-decreasing first)."""
    n = t.size
    s = t.copy()
    for i in range(1, n):
        s[i] = max(s[i], s[i - 1])
    distinct = 1
    for i in range(1, n):
        distinct += s[i] > s[i - 1]
    if distinct == n:
        return s
    steps = np.empty(distinct - 1)
    k = 0
    for i in range(1, n):
        if s[i] > s[i - 1]:
            steps[k] = s[i] - s[i - 1]
            k += 1
    interval = np.median(steps) if steps.size else 0.0
    a = 0
    while a < n:
        b = a + 1
        while b < n and s[b] == s[a]:
            b += 1
        width = s[b] - s[a] if b < n else interval
        spacing = min(width / (b - a), interval)
        for r in range(1, b - a):
            s[a + r] = s[a] + spacing * r
        a = b
    return s


@compiled
def regular(t: np.ndarray, width: float, gap: float) -> np.ndarray:
    """:func:`tagbot.inputs.stamps.regular_instants` of increasing stamps ``t``."""
    n = t.size
    out = t.copy()
    positive = 0
    for i in range(n - 1):
        positive += t[i + 1] > t[i]
    if positive < 2:
        return out
    steps = np.empty(positive)
    k = 0
    for i in range(n - 1):
        if t[i + 1] > t[i]:
            steps[k] = t[i + 1] - t[i]
            k += 1
    limit = gap * np.median(steps)
    reach = math.ceil(3.0 * width)
    weight = np.empty(2 * reach + 1)
    for d in range(-reach, reach + 1):
        weight[d + reach] = math.exp(-0.5 * (d / width) ** 2)
    start = 0
    while start < n:
        stop = start + 1
        while stop < n and t[stop] - t[stop - 1] <= limit:
            stop += 1
        if stop - start >= 3:
            for i in range(start, stop):
                s0 = s1 = s2 = t0 = t1 = 0.0
                for j in range(max(start, i - reach), min(stop, i + reach + 1)):
                    d = j - i
                    w = weight[d + reach]
                    s0 += w
                    s1 += w * d
                    s2 += w * d * d
                    t0 += w * t[j]
                    t1 += w * d * t[j]
                det = s0 * s2 - s1 * s1
                if det > 1e-12:
                    out[i] = (t0 * s2 - t1 * s1) / det
        start = stop
    for i in range(1, n):
        out[i] = max(out[i], out[i - 1])
    return out


@compiled
def roughness(t: np.ndarray, xy: np.ndarray) -> float:
    """:func:`tagbot.inputs.stamps.roughness`: ``Σ|Δv|² / Σ|v|²`` of the sample differences'
    velocity under instants ``t`` (intervals of length 0 left out)."""
    energy = change = 0.0
    count = 0
    px = py = 0.0
    for i in range(t.size - 1):
        dt = t[i + 1] - t[i]
        if not dt > 0.0:
            continue
        vx = (xy[i + 1, 0] - xy[i, 0]) / dt
        vy = (xy[i + 1, 1] - xy[i, 1]) / dt
        energy += vx * vx + vy * vy
        if count > 0:
            change += (vx - px) ** 2 + (vy - py) ** 2
        px, py = vx, vy
        count += 1
    if count < 3 or not energy > 0.0:
        return 0.0
    return change / energy


@compiled
def sample_instants(
    t: np.ndarray, xy: np.ndarray, width: float, gap: float, steady: float, blends: np.ndarray
) -> tuple[np.ndarray, float]:
    """:func:`tagbot.inputs.stamps.sample_instants`."""
    s = spread(t)
    positive = 0
    for i in range(s.size - 1):
        positive += s[i + 1] > s[i]
    if positive < 3:
        return s, 0.0
    steps = np.empty(positive)
    k = 0
    for i in range(s.size - 1):
        if s[i + 1] > s[i]:
            steps[k] = s[i + 1] - s[i]
            k += 1
    median = np.median(steps)
    worst = 0.0
    for k in range(positive):
        worst = max(worst, abs(steps[k] - median))
    if worst <= steady * median:
        return s, 0.0
    even = regular(s, width, gap)
    best, blend = roughness(s, xy), 0.0
    out = s
    candidate = np.empty(s.size)
    for b in blends:
        if b == 0.0:
            continue
        for i in range(s.size):
            candidate[i] = (1.0 - b) * s[i] + b * even[i]
        score = roughness(candidate, xy)
        if score < best * (1.0 - TIE):  # a tie (the instants equal the stamps) keeps the stamps
            best, blend = score, b
            out = candidate.copy()
    return out, blend
