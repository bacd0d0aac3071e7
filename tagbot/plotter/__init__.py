"""Pen plotters driven by Grbl: machine profiles, placement and retiming, G-code programs.

Usage::

    from tagbot.plotter import load_profile, place, build_program
    profile = load_profile("default", overrides=["bed.margin=5"])
    setpoints = place(tag, profile)      # machine mm, uniformly retimed to the machine's limits
    program = build_program(setpoints, profile)
    program.write("tag.gcode")
"""

from tagbot.plotter.place import Setpoints, place
from tagbot.plotter.profile import Profile, ProfileError, load_profile
from tagbot.plotter.program import Program, build_program

__all__ = [
    "Profile",
    "ProfileError",
    "Program",
    "Setpoints",
    "build_program",
    "load_profile",
    "place",
]
