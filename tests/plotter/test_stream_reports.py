"""What a stream's report and trace say about a hold tagbot asked for (issue 34)."""

from __future__ import annotations

from sim.grbl import SimulatedGrbl

from .test_stream import SETTINGS, connected, square_program


def test_an_asked_hold_is_one_pause_from_its_hold_to_its_resume_and_the_trace_has_the_wire():
    device = SimulatedGrbl(SETTINGS, pen_servo=(30, 50))
    port, streamer, wire = connected(device)
    connect_rx = b"".join(wire.rx)
    lines = square_program(600)
    events: dict[str, float] = {}

    def progress(done: int, total: int) -> None:
        if done >= 200 and "hold" not in events:
            streamer.hold()
            events["hold"] = streamer.clock.now()

    def resume_later(direction: str, data: bytes) -> None:
        wire(direction, data)
        held = events.get("hold")
        if held is not None and "resume" not in events and streamer.clock.now() > held + 1.5:
            streamer.resume()
            events["resume"] = streamer.clock.now()

    streamer._trace = resume_later
    try:
        report = streamer.stream(lines, progress=progress)
    finally:
        port.close()
    assert report.lines_acknowledged == len(lines) and report.errors == []
    # Asked for: one pause from the "!" sent to the "~" sent, not a hold from outside.
    assert report.pauses == 1 and report.outside_holds == 0 and report.warnings == []
    ((start, length),) = report.pause_spans
    assert events["hold"] <= start < events["resume"] <= start + length
    assert report.paused_s == length < report.duration
    # The trace hook saw every byte received: the banner at connect, an ok per line streamed.
    assert b"Grbl 1.1" in connect_rx
    received = b"".join(wire.rx)[len(connect_rx) :]
    assert received.count(b"ok\r\n") == len(lines)
