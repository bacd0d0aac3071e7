"""The real dynamixel-sdk against the simulated chain: in-process (``dxlsim://``) and over a pty."""

from __future__ import annotations

import os
import threading
import time

import dynamixel_sdk as dxl
import numpy as np
import pytest
import serial

import sim.dynamixel  # registers dxlsim://
from sim.dynamixel import PtyServer, SimulatedChain, attach_chain, detach_chain, serve_pty
from sim.dynamixel.protocol_dxlsim import Serial as DxlSimSerial
from sim.pty import DEVICE_PRIORITY

ALERT = 0x80


class UrlPortHandler(dxl.PortHandler):
    """The SDK's port handler opening a pyserial URL (what the DESIGN notes suggest)."""

    def setupPort(self, cflag_baud):
        if self.is_open:
            self.closePort()
        self.ser = serial.serial_for_url(self.port_name, baudrate=self.baudrate, timeout=0)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


class SimTimePortHandler(UrlPortHandler):
    """... whose packet timeouts also run on the port's simulated clock."""

    def getCurrentTime(self):
        return self.ser.clock.now() * 1000.0


@pytest.fixture
def ph() -> dxl.Protocol2PacketHandler:
    return dxl.PacketHandler(2.0)


@pytest.fixture
def chain():
    chain = SimulatedChain({3: "XL430-W250", 1: "XM430-W350", 2: "XL430-W250"})
    url = attach_chain(chain, "arm")
    assert url == "dxlsim://arm"
    yield chain
    detach_chain("arm")


@pytest.fixture
def port(chain):
    port = SimTimePortHandler("dxlsim://arm")
    assert port.openPort()
    yield port
    port.closePort()


def test_url_handler_and_its_options():
    port = serial.serial_for_url("dxlsim://?ids=4,2&models=XM430-W350,1060&baud=57600", timeout=0)
    try:
        assert isinstance(port, serial.SerialBase) and isinstance(port, DxlSimSerial)
        assert port.chain.ids == (2, 4) and port.chain.baud == 57_600
        assert port.chain.servo(4).table.model_name == "XM430-W350"
        assert port.chain.servo(2).table.model_number == 1060
        assert port.clock.now() == 0.0
    finally:
        port.close()
    for url, message in (
        ("dxlsim://?ids=1&colour=red", "unknown option"),
        ("dxlsim://?models=XL430-W250", "ids"),
        ("dxlsim://?ids=1,2&models=XL430-W250,XL430-W250,XL430-W250", "models"),
        ("dxlsim://?ids=1&models=AX-12", "model"),
        ("dxlsim://?ids=1&baud=12345", "baud"),
        ("dxlsim://nobody", "no chain attached"),
    ):
        with pytest.raises(serial.SerialException, match=message):
            serial.serial_for_url(url)
    with pytest.raises(ValueError, match="identifier"):
        attach_chain(SimulatedChain({1: 1060}), "not-a-name")
    with pytest.raises(ValueError, match="simulated"):
        attach_chain(SimulatedChain({1: 1060}, clock="real"), "walltime")


def test_clock_contract(chain):
    port = serial.serial_for_url("dxlsim://arm", timeout=0.25)
    try:
        clock = port.clock
        clock.sleep_until(1.5)
        assert clock.now() == 1.5 == chain.now()
        clock.sleep_until(1.0)  # the past: nothing happens
        assert clock.now() == 1.5
        wall = time.perf_counter()
        assert port.read(1) == b""  # nothing coming: the timeout passes in simulated time
        assert clock.now() == pytest.approx(1.75)
        assert time.perf_counter() - wall < 0.1
        port.write(bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E"))  # PING 1
        reply = port.read(14)
        assert len(reply) == 14
        # 10 bytes out, 500 µs Return Delay Time, 14 bytes back, at 10 µs a byte
        assert clock.now() == pytest.approx(1.75 + 10e-6 * 24 + 500e-6)
        port.timeout = None
        assert port.read(5) == b""  # nothing can arrive: returns rather than hang
    finally:
        port.close()


def test_sdk_ping_broadcast_ping_and_read_write(port, ph, chain):
    assert ph.ping(port, 1) == (1020, dxl.COMM_SUCCESS, 0)
    assert ph.ping(port, 9)[1] == dxl.COMM_RX_TIMEOUT
    found, result = ph.broadcastPing(port)
    assert result == dxl.COMM_SUCCESS
    assert list(found.items()) == [(1, [1020, 46]), (2, [1060, 46]), (3, [1060, 46])]
    assert ph.write1ByteTxRx(port, 2, 64, 1) == (dxl.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, 7, 9) == (dxl.COMM_SUCCESS, 7)  # EEPROM locked: access
    assert ph.write4ByteTxRx(port, 2, 116, 5000) == (dxl.COMM_SUCCESS, 6)  # data limit
    assert ph.write4ByteTxRx(port, 2, 116, 2548) == (dxl.COMM_SUCCESS, 0)
    port.ser.clock.sleep_until(port.ser.clock.now() + 1.0)
    assert ph.read4ByteTxRx(port, 2, 132) == (2548, dxl.COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 1, 0) == (1020, dxl.COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 3, 9) == (250, dxl.COMM_SUCCESS, 0)


def test_sdk_group_sync_write_read_fast_and_bulk(port, ph, chain):
    for id in (1, 2, 3):
        assert ph.write1ByteTxRx(port, id, 64, 1) == (dxl.COMM_SUCCESS, 0)
    writer = dxl.GroupSyncWrite(port, ph, 116, 4)
    for id in (1, 2, 3):
        assert writer.addParam(id, list((1000 * id).to_bytes(4, "little")))
    assert writer.txPacket() == dxl.COMM_SUCCESS
    port.ser.clock.sleep_until(port.ser.clock.now() + 1.0)
    reader = dxl.GroupSyncRead(port, ph, 132, 4)
    for id in (1, 2, 3):
        assert reader.addParam(id)
    assert reader.txRxPacket() == dxl.COMM_SUCCESS
    assert [reader.getData(id, 132, 4) for id in (1, 2, 3)] == [1000, 2000, 3000]
    assert reader.fastSyncRead() == dxl.COMM_SUCCESS
    assert [reader.getData(id, 132, 4) for id in (1, 2, 3)] == [1000, 2000, 3000]
    bulk = dxl.GroupBulkRead(port, ph)
    assert bulk.addParam(1, 132, 4) and bulk.addParam(3, 9, 1)
    assert bulk.txRxPacket() == dxl.COMM_SUCCESS
    assert (bulk.getData(1, 132, 4), bulk.getData(3, 9, 1)) == (1000, 250)


def test_sdk_sees_every_fault_hook(port, ph, chain):
    chain.silence(2)
    assert ph.ping(port, 2)[1] == dxl.COMM_RX_TIMEOUT
    assert ph.write1ByteTxRx(port, 2, 65, 1)[0] == dxl.COMM_RX_TIMEOUT
    assert chain.servo(2).get("led") == 1  # executed, though silent
    chain.silence(2, on=False)
    chain.corrupt_next(1)
    assert ph.ping(port, 1)[1] == dxl.COMM_RX_CORRUPT
    assert ph.ping(port, 1) == (1020, dxl.COMM_SUCCESS, 0)
    chain.set_model_number(3, 1200)
    assert ph.ping(port, 3)[0] == 1200
    assert ph.write1ByteTxRx(port, 3, 64, 1) == (dxl.COMM_SUCCESS, 0)
    chain.set_hardware_error(3, 0x04)  # overheating: shutdown
    value, result, error = ph.read1ByteTxRx(port, 3, 70)
    assert (value, result) == (0x04, dxl.COMM_SUCCESS) and error & ALERT
    assert ph.read1ByteTxRx(port, 3, 64)[0] == 0
    assert ph.reboot(port, 3) == (dxl.COMM_SUCCESS, ALERT)
    port.ser.clock.sleep_until(port.ser.clock.now() + 0.2)
    assert ph.ping(port, 3)[2] == 0  # error byte clean after the reboot


def test_sdk_with_wall_clock_timeouts(chain, ph):
    port = UrlPortHandler("dxlsim://arm")  # only setupPort overridden
    assert port.openPort()
    try:
        assert ph.ping(port, 3) == (1060, dxl.COMM_SUCCESS, 0)
        chain.silence(3)
        wall = time.perf_counter()
        assert ph.ping(port, 3)[1] == dxl.COMM_RX_TIMEOUT
        assert time.perf_counter() - wall < 0.5  # the SDK's ~34 ms, in wall-clock time
    finally:
        port.closePort()


def test_streaming_setpoints_runs_faster_than_real_time(port, ph, chain):
    for id in (2, 3):  # both XL430-W250 (the XM430-W350's lower Velocity Limit would stretch)
        assert ph.write1ByteTxRx(port, id, 10, 4) == (dxl.COMM_SUCCESS, 0)  # time-based
        assert ph.write4ByteTxRx(port, id, 112, 20) == (dxl.COMM_SUCCESS, 0)  # 20 ms a move
        assert ph.write1ByteTxRx(port, id, 64, 1) == (dxl.COMM_SUCCESS, 0)
    clock = port.ser.clock
    writer = dxl.GroupSyncWrite(port, ph, 116, 4)
    dt, ticks = 0.01, 10_000  # 100 Hz for 100 s
    start = clock.now()
    wall = time.perf_counter()
    for k in range(ticks):
        goal = 2048 + round(1000 * np.sin(2 * np.pi * 0.5 * k * dt))
        writer.clearParam()
        for id in (2, 3):
            writer.addParam(id, list(goal.to_bytes(4, "little")))
        assert writer.txPacket() == dxl.COMM_SUCCESS
        clock.sleep_until(start + (k + 1) * dt)
    assert time.perf_counter() - wall < 10.0
    assert clock.now() == pytest.approx(start + ticks * dt)
    t, p = chain.trace(2).T
    # each setpoint is reached 20 ms after its tick: the servo follows the sine, 20 ms late
    window = (t > start + 1.0) & (t < start + ticks * dt - 0.1)
    expected = 2048 + 1000 * np.sin(2 * np.pi * 0.5 * (t[window] - start - 0.02))
    assert np.max(np.abs(p[window] - expected)) < 2.0
    assert np.array_equal(chain.trace(3)[:, 1], p)


def test_pty_with_the_unmodified_sdk(ph):
    chain = SimulatedChain({1: "XL430-W250", 2: "XM430-W350"}, clock="real")
    before = set(threading.enumerate())
    server = PtyServer(chain)
    port = dxl.PortHandler(server.path)
    try:
        assert port.openPort()
        assert port.setBaudRate(1_000_000)  # a pty ignores the speed; the chain runs at 1 Mbit/s
        assert ph.ping(port, 2) == (1020, dxl.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, 10, 4) == (dxl.COMM_SUCCESS, 0)
        assert ph.write4ByteTxRx(port, 1, 112, 100) == (dxl.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, 64, 1) == (dxl.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, 9, 0) == (dxl.COMM_SUCCESS, 7)
        assert ph.write4ByteTxRx(port, 1, 116, 2148) == (dxl.COMM_SUCCESS, 0)
        time.sleep(0.15)
        assert ph.read4ByteTxRx(port, 1, 132) == (2148, dxl.COMM_SUCCESS, 0)
        reader = dxl.GroupSyncRead(port, ph, 132, 4)
        assert reader.addParam(1) and reader.addParam(2)
        assert reader.txRxPacket() == dxl.COMM_SUCCESS
        assert (reader.getData(1, 132, 4), reader.getData(2, 132, 4)) == (2148, 2048)
        found, result = ph.broadcastPing(port)
        assert result == dxl.COMM_SUCCESS and sorted(found) == [1, 2]
        chain.silence(2)
        assert ph.ping(port, 2)[1] == dxl.COMM_RX_TIMEOUT
    finally:
        port.closePort()
        server.stop()
    server.stop()  # idempotent
    assert set(threading.enumerate()) == before
    assert server._master is None and server._slave is None
    with pytest.raises(OSError):  # the pseudo-terminal is gone
        os.close(os.open(server.path, os.O_RDWR | os.O_NOCTTY))


def _may_run_real_time() -> bool:
    """Whether this process may use SCHED_FIFO (root, CAP_SYS_NICE or an rtprio limit)."""
    try:
        before = (os.sched_getscheduler(0), os.sched_getparam(0))
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        return False
    os.sched_setscheduler(0, *before)
    return True


def test_the_pty_pump_runs_real_time_like_a_devices_own_processor_where_permitted():
    chain = SimulatedChain({1: "XL430-W250"}, clock="real")
    server = PtyServer(chain)
    try:
        if _may_run_real_time():
            assert server.realtime.wait(2.0)
            native = server._thread.native_id
            assert os.sched_getscheduler(native) == os.SCHED_FIFO
            assert os.sched_getparam(native).sched_priority == DEVICE_PRIORITY
        else:
            time.sleep(0.05)
            assert not server.realtime.is_set()
    finally:
        server.stop()
    assert os.sched_getscheduler(0) != os.SCHED_FIFO  # the caller's own thread is untouched


def test_serve_pty_needs_a_real_time_chain():
    with pytest.raises(ValueError, match="clock='real'"):
        serve_pty(SimulatedChain({1: "XL430-W250"}))
    path, stop = serve_pty(SimulatedChain({1: "XL430-W250"}, clock="real"))
    try:
        with serial.Serial(path, timeout=0.2) as raw:
            raw.write(bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E"))
            reply = raw.read(14)
        assert reply[:9] == bytes.fromhex("FF FF FD 00 01 07 00 55 00")
    finally:
        stop()


def test_importing_the_package_registers_the_scheme():
    assert "sim.dynamixel" in serial.protocol_handler_packages
    assert sim.dynamixel.register() is None  # idempotent
    assert serial.protocol_handler_packages.count("sim.dynamixel") == 1
