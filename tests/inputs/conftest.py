"""Shared helpers of the input tests: the fixture folder and a GML builder."""

from __future__ import annotations

from pathlib import Path

DATA = Path(__file__).resolve().parent / "data"
"""Small input files owned by the project (see data/README.md)."""


def gml(*strokes: str, environment: str = "", root: str = "gml") -> bytes:
    """A GML document with one tag and one drawing holding ``strokes`` (XML fragments)."""
    env = f"<environment>{environment}</environment>" if environment else ""
    body = "".join(strokes)
    return f"<{root}><tag>{env}<drawing>{body}</drawing></tag></{root}>".encode()


def stroke(*points: tuple, time_tag: str = "t", attrs: str = "") -> str:
    """A ``<stroke>`` of points ``(x, y)`` or ``(x, y, time)``; time None writes no time."""
    pts = []
    for p in points:
        time = f"<{time_tag}>{p[2]}</{time_tag}>" if len(p) > 2 and p[2] is not None else ""
        pts.append(f"<pt><x>{p[0]}</x><y>{p[1]}</y>{time}</pt>")
    return f"<stroke{attrs}>{''.join(pts)}</stroke>"
