"""The simulated EBB's RC servo channels as firmware 3.0 has them (reference "S2", "SC"; source
``RCServo2_Move``, ``RCServo2_get_channel_from_RPn``, ``RCServo2_S2_command``): ``S2`` without
a pin is RP0's, not the pen's; a servo move on a channel beyond ``SC,8``'s count, or with none
free, is answered ``OK`` and ignored; ``SC,8``/``SC,9`` clamp as the firmware does."""

from __future__ import annotations

import pytest

from sim.ebb import SimulatedEBB

OK = b"OK\r\n"
BOOT_UP = 22565
"""The pen's pulse width at boot (up), on RP4, channel 1."""


def send(device: SimulatedEBB, *lines: bytes, wait: float = 0.05) -> bytes:
    """Write ``lines`` (each gets its CR), run ``wait`` simulated seconds, return the replies."""
    device.write(b"".join(line + b"\r" for line in lines))
    device.advance(wait)
    return device.read()


def ignored(device: SimulatedEBB) -> list[str]:
    return [text for _, text in device.recorder.events if "ignored" in text]


def test_s2_without_a_pin_is_rp0s_and_leaves_the_pen_pulsing():
    device = SimulatedEBB()
    assert device.pen_position() == BOOT_UP
    assert send(device, b"S2,0") == OK  # turns off RP0, which has no channel
    assert send(device, b"S2,12000", wait=0.2) == OK  # a pulse on RP0: not the pen's pin
    assert device.pen_position() == BOOT_UP
    assert send(device, b"S2,12000,4", wait=0.2) == OK  # RP4 named: the pen moves
    assert device.pen_position() == 12000
    assert send(device, b"S2,0,4") == OK
    assert device.pen_position() == 0  # its output off at once


def test_a_servo_move_beyond_sc_8s_channels_is_answered_and_ignored():
    """With one channel (the pen's, channel 1) an S2 on another pin would need channel 2:
    ``OK``, nothing queued (its delay holds nothing back); with two it is queued."""
    device = SimulatedEBB()
    assert send(device, b"SC,8,1", b"S2,20000,6,0,200", b"SM,10,1,0", wait=0.1) == OK * 3
    device.run_until_idle()
    (move,) = [s for s in device.recorder.segments if s.kind == "move"]
    assert move.load_tick < 25 * 10  # at once: no 200 ms servo delay before it
    assert ignored(device) == ["S2 on RP6 ignored: channel 2, SC,8 allows 1"]
    assert device.channels[:2] == [4, 0]
    # The pen, on channel 1, still moves.
    assert send(device, b"SC,4,16000", b"SP,1", wait=0.3) == OK * 2
    assert device.pen_position() == 16000
    # Two channels: the same S2 takes channel 2 and its delay holds the next move back.
    device = SimulatedEBB()
    assert send(device, b"SC,8,2", b"S2,20000,6,0,200", b"SM,10,1,0", wait=0.1) == OK * 3
    device.run_until_idle()
    servo, move = device.recorder.segments[-2:]
    assert servo.kind == "servo" and move.load_tick == servo.end_tick
    assert device.channels[:2] == [4, 6] and not ignored(device)


def test_a_pen_on_a_channel_beyond_the_count_gets_no_pulse_and_ignores_sp():
    device = SimulatedEBB()
    # RP6 takes channel 1 once RP4 has let it go; the pen then takes channel 2.
    assert send(device, b"S2,0,4", b"S2,20000,6", b"SP,1", wait=0.3) == OK * 3
    assert device.channels[:2] == [6, 4] and device.pen_position() == BOOT_UP
    assert send(device, b"SC,8,1") == OK
    assert device.pen_position() == 0  # channel 2 is no longer pulsed
    assert send(device, b"SP,0,100", wait=0.3) == OK
    assert device.pen_position() == 0
    assert ignored(device) == ["SP on RP4 ignored: channel 2, SC,8 allows 1"]


def test_a_ninth_pin_finds_no_channel():
    device = SimulatedEBB()
    pins = [5, 6, 7, 8, 9, 10, 11]  # channels 2-8 (the pen has 1)
    assert send(device, *(b"S2,20000,%d" % p for p in pins), wait=0.2) == OK * 7
    assert device.channels == [4, *pins]
    assert send(device, b"S2,20000,13") == OK
    assert ignored(device) == ["S2 on RP13 ignored: no channel free, SC,8 allows 8"]
    assert send(device, b"S2,0,9", b"S2,20000,13", wait=0.2) == OK * 2  # RP9 frees one
    assert device.channels == [4, 5, 6, 7, 8, 13, 10, 11]


@pytest.mark.parametrize(
    ("lines", "channels", "slot_ms"),
    [
        ((b"SC,8,9",), 8, 3),  # 1 to 8 are valid: above, 8
        ((b"SC,8,3", b"SC,9,7"), 3, 6),  # 1 to 6 ms: above, 6
        ((b"SC,8,3", b"SC,9,0"), 3, 1),  # 0 acts as 1 ms
    ],
)
def test_sc_8_and_9_clamp_as_the_firmware(lines, channels, slot_ms):
    device = SimulatedEBB()
    assert send(device, *lines, b"SC,4,16000", b"SP,1", wait=0.5) == OK * (len(lines) + 2)
    assert (device.servo_channels, device.servo_slot_ms) == (channels, slot_ms)
    moving = device.recorder.servo[-1]
    assert moving.target == 16000 and moving.period == pytest.approx(channels * slot_ms / 1e3)
