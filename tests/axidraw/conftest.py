"""Shared fixtures: a packaged example tag placed on the AxiDraw V3, and its job."""

from __future__ import annotations

from pathlib import Path

import pytest

import tagbot
from tagbot.axidraw.moves import build_job
from tagbot.axidraw.profile import load_profile
from tagbot.io.planfile import load_plan
from tagbot.plotter.place import place

LETTER_B = Path(tagbot.__file__).parent / "examples" / "letter-b.json"
CAE = Path(tagbot.__file__).parent / "examples" / "cae.json"


@pytest.fixture
def cae_job():
    """The three-run example, its placement and its job on the default profile.

    Built for each test (about 0.5 s), not shared: mutmut runs, for a mutant, only the tests
    that called its function themselves, so a shared job would leave all but the first out."""
    tag = load_plan(CAE)
    profile = load_profile()
    setpoints = place(tag, profile.placement())
    return tag, profile, setpoints, build_job(tag, setpoints, profile)
