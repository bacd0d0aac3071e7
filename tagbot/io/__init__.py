"""File formats: plan files (JSON) in :mod:`tagbot.io.planfile`, motion CSV in
:mod:`tagbot.io.motionfile`.

The submodules are imported on demand so that, e.g., reading a motion CSV does not load the model.
"""
