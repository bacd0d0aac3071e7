"""Pause and resume requests for a running machine, made from any thread (the terminal's keys).

A back end polls :attr:`RunControl.paused` at its own pace (each loop of the G-code stream, each
tick of the arm) and acts on a change: the plotter sends a feed hold (``!``) and later a resume
(``~``); the arm lifts its pen, holds its pose and, on resume, lowers the pen and goes on where it
stopped. Nothing here touches a port.
"""

from __future__ import annotations

import threading

__all__ = ["RunControl"]


class RunControl:
    """A pause flag shared between whoever asks (a key press) and the loop that obeys."""

    def __init__(self) -> None:
        self._paused = threading.Event()

    @property
    def paused(self) -> bool:
        """True from :meth:`pause` until :meth:`resume`."""
        return self._paused.is_set()

    def pause(self) -> None:
        self._paused.set()

    def resume(self) -> None:
        self._paused.clear()

    def toggle(self) -> bool:
        """Pause if running, resume if paused; returns the new :attr:`paused`."""
        if self.paused:
            self.resume()
        else:
            self.pause()
        return self.paused
