"""One exception tree for tagbot.

Every error tagbot raises on purpose derives from :class:`TagbotError`, so callers can catch the
whole family at once. Bad arguments and bad input files are also :class:`ValueError` (the Python
convention), and their messages start by naming the offending field, e.g.
``plans[0].strokes[2].sigma: must be > 0, got -1.0``.
"""

from __future__ import annotations


class TagbotError(Exception):
    """Base class of every error tagbot raises on purpose."""


class PlanError(TagbotError, ValueError):
    """A plan, tag or model parameter is invalid; the message names the field."""


class PlanFileError(PlanError):
    """A plan file cannot be read: not JSON, wrong format or version, or invalid content."""


class InputError(TagbotError, ValueError):
    """An input file (trace, motion, profile) is unreadable or invalid."""
