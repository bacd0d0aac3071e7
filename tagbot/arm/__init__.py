"""A drawing arm of DYNAMIXEL X-series servos: profiles, kinematics, placement, streaming.

Usage::

    from tagbot.arm import load_profile, draw_arm
    profile = load_profile("default", overrides=["motion.rate=200"])
    run = draw_arm(tag, profile)                 # a simulated servo chain, in simulated time
    run = draw_arm(tag, profile, "/dev/ttyUSB0")  # the real arm (or a `tagbot sim arm` pty)
    run.setpoints, run.joints, run.executed, run.stats

    job = prepare(tag, overrides=["motion.rate=200"], port=None)  # checked, nothing sent yet
    machine_run = job.run(folder, progress=..., control=RunControl())  # tagbot draw's contract

:func:`~tagbot.arm.place.build_program` alone places, retimes and checks a tag without any
device (PlacementError before the first packet).
"""

from tagbot._lazy import lazy_exports

_EXPORTS = {
    **dict.fromkeys(["Arm"], ".kinematics"),
    **dict.fromkeys(
        ["ArmProgram", "Placement", "Setpoints", "build_program", "check_program", "place"],
        ".place",
    ),
    **dict.fromkeys(
        ["ArmProfile", "ProfileError", "load_profile", "packaged_profiles"], ".profile"
    ),
    **dict.fromkeys(["ArmJob", "ArmRun", "draw_arm", "latency_timer_warning", "prepare"], ".run"),
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "Arm",
    "ArmJob",
    "ArmProfile",
    "ArmProgram",
    "ArmRun",
    "Placement",
    "ProfileError",
    "Setpoints",
    "build_program",
    "check_program",
    "draw_arm",
    "latency_timer_warning",
    "load_profile",
    "packaged_profiles",
    "place",
    "prepare",
]
