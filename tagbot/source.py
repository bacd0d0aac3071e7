"""What the commands draw: a plan file as is, or any trace file fitted first.

``tagbot gcode``, ``draw``, ``render`` and ``plot`` all accept ``INPUT|PLAN``: the file is read
once through the bounded input reader, a tagbot plan is recognised by its ``format`` field, and
anything else is read as traces (GML, #000000book JSON, SVG, points, UNIPEN) and fitted.
"""

from __future__ import annotations

import json
import logging
from typing import TYPE_CHECKING

from tagbot.errors import PlanError

if TYPE_CHECKING:  # numba and scipy load only once a file is read and found usable
    from tagbot.inputs import Trace
    from tagbot.model.plan import Tag

__all__ = ["load_source", "load_tag", "read_source"]

log = logging.getLogger("tagbot.fit")
"""Where a fit says how it timed the traces it could not match (one line each, naming the
file); the command line prints them as ``tagbot: warning: …``."""


def load_source(path: str, model: str | None = None) -> tuple[Tag, list[Trace] | None]:
    """The tag in ``path`` and, for a trace file, its traces (fitted with ``model``, default
    gamma). A plan file is returned as is, with ``None`` for the traces."""
    from tagbot.inputs import read_input

    return read_source(read_input(path), path, model)  # bounded like every input


def read_source(data: bytes, name: str, model: str | None = None) -> tuple[Tag, list[Trace] | None]:
    """:func:`load_source` for a file's bytes already read (an upload); ``name`` is used in
    errors."""
    from tagbot.inputs import read_traces_bytes

    try:
        document = json.loads(data.decode("utf-8-sig"))
    except (ValueError, UnicodeDecodeError):
        document = None
    if isinstance(document, dict) and document.get("format") == "tagbot-plan":
        from tagbot.io.planfile import tag_from_dict

        try:
            return tag_from_dict(document), None
        except PlanError as e:
            raise type(e)(f"{name}: {e}") from e
    traces = read_traces_bytes(data, name)
    from tagbot.gesture import reconstruction  # after reading: a bad file is refused first

    try:
        fitted = reconstruction(traces, model=model or "gamma")
    except PlanError as e:  # e.g. a tag longer than a tag may last: which file
        raise type(e)(f"{name}: {e}") from e
    for note in fitted.notes():  # e.g. a clock no hand can produce, and what the fit did
        log.warning("%s: %s", name, note)
    return fitted.tag, traces


def load_tag(path: str, model: str | None = None) -> Tag:
    """The tag in ``path``: a plan file as is, a trace file fitted with ``model``."""
    return load_source(path, model)[0]
