"""Serial arms from a robot description (issue 32): the shipped MJCF models and IK by mink."""

from __future__ import annotations

from pathlib import Path

MODELS = Path(__file__).parent / "models"
"""The folder of the shipped robot descriptions (MJCF)."""

OPEN_MANIPULATOR_X = MODELS / "open_manipulator_x.xml"
"""ROBOTIS OpenManipulator-X holding a pen (``pen_tip`` site 0.03 m beyond the end effector)."""
