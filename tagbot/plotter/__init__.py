"""Pen plotters driven by Grbl: machine profiles, placement and retiming, G-code programs.

Usage::

    from tagbot.plotter import load_profile, place, build_program
    profile = load_profile("default", overrides=["bed.margin=5"])
    setpoints = place(tag, profile)      # machine mm, uniformly retimed to the machine's limits
    program = build_program(setpoints, profile)
    program.write("tag.gcode")
"""

from tagbot._lazy import lazy_exports

_EXPORTS = {
    **dict.fromkeys(["Setpoints", "place"], ".place"),
    **dict.fromkeys(["Profile", "ProfileError", "load_profile"], ".profile"),
    **dict.fromkeys(["Program", "build_program"], ".program"),
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "Profile",
    "ProfileError",
    "Program",
    "Setpoints",
    "build_program",
    "load_profile",
    "place",
]
