"""What the commands draw: a plan file as is, or any trace file fitted first.

``tagbot gcode``, ``draw``, ``render`` and ``plot`` all accept ``INPUT|PLAN``: the file is read
once through the bounded input reader, a tagbot plan is recognised by its ``format`` field, and
anything else is read as traces (GML, #000000book JSON, SVG, points) and fitted.
"""

from __future__ import annotations

import json

from tagbot.errors import PlanError
from tagbot.inputs import Trace
from tagbot.model.plan import Tag

__all__ = ["load_source", "load_tag"]


def load_source(path: str, model: str | None = None) -> tuple[Tag, list[Trace] | None]:
    """The tag in ``path`` and, for a trace file, its traces (fitted with ``model``, default
    gamma). A plan file is returned as is, with ``None`` for the traces."""
    from tagbot.gesture import fit
    from tagbot.inputs import read_input, read_traces_bytes
    from tagbot.io.planfile import tag_from_dict

    data = read_input(path)  # bounded like every input
    try:
        document = json.loads(data.decode("utf-8-sig"))
    except (ValueError, UnicodeDecodeError):
        document = None
    if isinstance(document, dict) and document.get("format") == "tagbot-plan":
        try:
            return tag_from_dict(document), None
        except PlanError as e:
            raise type(e)(f"{path}: {e}") from e
    traces = read_traces_bytes(data, path)
    return fit(traces, model=model or "gamma"), traces


def load_tag(path: str, model: str | None = None) -> Tag:
    """The tag in ``path``: a plan file as is, a trace file fitted with ``model``."""
    return load_source(path, model)[0]
