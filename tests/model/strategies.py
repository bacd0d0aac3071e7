"""Hypothesis strategies and builders for random plans (shared by the model tests)."""

import itertools

import numpy as np
from hypothesis import strategies as st

from tagbot.model.plan import DEFAULT_MU, DEFAULT_SIGMA, Plan


def random_plan(rng: np.random.Generator, m: int, start: float = 0.0, sigma_model=False) -> Plan:
    """A plausible random plan of ``m`` targets (steps of ~30 mm, dt in [0, 0.4] s)."""
    targets = np.cumsum(rng.normal(size=(m, 2)) * 30.0, axis=0)
    n = m - 1
    dt = rng.uniform(0.0, 0.4, n)
    mu = DEFAULT_MU + rng.normal(0.0, 0.2, n)
    sigma = DEFAULT_SIGMA * rng.uniform(0.6, 1.5, n)
    if sigma_model:
        return Plan.sigma_model(targets, dt, mu, sigma, rng.uniform(-2.5, 2.5, n), start)
    return Plan(targets, dt, mu, sigma, rng.uniform(-2.5, 2.5, n), rng.uniform(-2.5, 2.5, n), start)


@st.composite
def plans(draw, max_targets: int = 8, start: float = 0.0) -> Plan:
    """Random valid ΓΛ* plans: any overlap (dt from 0), wide mu/sigma, tangents in (−π, π)."""
    m = draw(st.integers(2, max_targets))
    coord = st.floats(-500.0, 500.0, allow_nan=False)
    targets = draw(
        st.lists(st.tuples(coord, coord), min_size=m, max_size=m, unique=True).filter(
            lambda pts: all(
                np.hypot(a[0] - b[0], a[1] - b[1]) > 1e-3 for a, b in itertools.pairwise(pts)
            )
        )
    )
    n = m - 1
    angle = st.floats(-3.1, 3.1)
    return Plan(
        targets,
        draw(st.lists(st.floats(0.0, 0.5), min_size=n, max_size=n)),
        draw(st.lists(st.floats(-2.5, -0.5), min_size=n, max_size=n)),
        draw(st.lists(st.floats(0.1, 0.6), min_size=n, max_size=n)),
        draw(st.lists(angle, min_size=n, max_size=n)),
        draw(st.lists(angle, min_size=n, max_size=n)),
        start,
    )
