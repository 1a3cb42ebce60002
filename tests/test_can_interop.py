"""Third-party hosts against ``boundswarm plant --drivers-only``: odrive-can's ODriveCAN, and
a python-can host sending only the bytes each command needs (as ODrive's python-can guide
and the odrive-cansimple crate do). Each arms an axis, drives it, reads its encoder
estimates, lets its watchdog trip (0.3 s here) and clears it to drive again."""
import asyncio
import struct
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest
from helpers import free_port

from transport.canbus import open_bus

ROOT = Path(__file__).resolve().parent.parent
GROUP = "ff11::b5:18"          # interface-local: the frames never leave the machine
WATCHDOG = 0.3                 # s, the emulated drivers' watchdog timeout
WATCHDOG_EXPIRED = 0x1000000


@pytest.fixture
def drivers_port():
    """A udp_multicast port with ``plant --drivers-only`` (nodes 0 and 1) serving on it."""
    port = free_port("udp6")
    proc = subprocess.Popen([sys.executable, "-m", "hil.cli", "plant", "--drivers-only",
                             "--can-interface", "udp_multicast", "--can-channel", GROUP,
                             "--can-port", str(port), "--watchdog", str(WATCHDOG)],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        yield port
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(timeout=10)
        if proc.stderr:
            proc.stderr.close()


def test_odrive_can_host_arms_drives_survives_and_clears_a_watchdog_trip(drivers_port):
    odrive = pytest.importorskip("odrive_can.odrive",
                                 reason="odrive-can (test extra) needs Python >= 3.11")
    bus = open_bus("udp_multicast", GROUP, port=drivers_port)
    drv = odrive.ODriveCAN(axis_id=0, can_bus=bus)
    estimates: list[dict] = []
    drv.feedback_callback = lambda msg, _: estimates.append(msg.data)

    async def drive(setpoint: float, seconds: float) -> None:
        """Set_Input_Vel every 20 ms (it feeds the watchdog) for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            drv.set_input_vel(setpoint)
            await asyncio.sleep(0.02)

    async def arm() -> None:
        feeder = asyncio.create_task(drive(0.0, 2.0))
        try:
            await drv.set_axis_state("CLOSED_LOOP_CONTROL")    # waits for the heartbeat
        finally:
            feeder.cancel()
        drv.check_errors()

    async def session() -> None:
        await asyncio.wait_for(drv.start(), 60.0)              # first heartbeat
        drv.clear_errors()
        drv.set_controller_mode("VELOCITY_CONTROL", "VEL_RAMP")
        await arm()
        await drive(2.0, 0.5)
        polled = await drv.get_encoder_estimates()             # a remote request
        assert polled["Vel_Estimate"] == pytest.approx(2.0, abs=0.05)
        assert estimates and estimates[-1]["Pos_Estimate"] > 0.5       # the cyclic ones
        await asyncio.sleep(WATCHDOG + 0.4)                    # the host falls silent
        await drv.wait_for_heartbeat()
        assert drv.axis_state == "IDLE"
        with pytest.raises(odrive.DriveError, match="WATCHDOG_TIMER_EXPIRED"):
            drv.check_errors()
        drv.clear_errors()                                      # Clear_Errors, 1 byte
        await drv.wait_for_heartbeat()
        drv.check_errors()                                      # cleared
        await arm()
        # from here the cyclic estimates: odrive-can may hand a later request an earlier
        # request's answer (seen on a loaded machine)
        await asyncio.sleep(0.05)
        before = estimates[-1]["Pos_Estimate"]
        await drive(-1.0, 0.5)
        after = estimates[-1]
        assert after["Vel_Estimate"] == pytest.approx(-1.0, abs=0.05)
        assert after["Pos_Estimate"] < before

    try:
        asyncio.run(session())
    finally:
        drv.stop()                                  # IDLE, ends its reader thread
        bus.shutdown()


class MinimalHost:
    """A python-can host that sends each command with only the bytes it needs."""

    def __init__(self, bus: can.BusABC, node: int):
        self.bus, self.node = bus, node
        self.state = self.error = None
        self.vel = self.pos = None

    def send(self, cmd: int, data: bytes = b"") -> None:
        self.bus.send(can.Message(arbitration_id=self.node << 5 | cmd, data=data,
                                  is_extended_id=False))

    def listen(self, seconds: float, vel: float | None = None) -> None:
        """Read heartbeats and encoder estimates for ``seconds``; with ``vel`` [rev/s],
        send it as Set_Input_Vel every 20 ms meanwhile."""
        end = next_cmd = time.monotonic()
        end += seconds
        while (now := time.monotonic()) < end:
            if vel is not None and now >= next_cmd:
                self.send(0x00D, struct.pack("<ff", vel, 0.0))
                next_cmd = now + 0.02
            msg = self.bus.recv(0.005)
            if msg is None or msg.arbitration_id >> 5 != self.node:
                continue
            if msg.arbitration_id & 0x1F == 0x001:
                self.error, self.state = struct.unpack_from("<IB", msg.data)
            elif msg.arbitration_id & 0x1F == 0x009:
                self.pos, self.vel = struct.unpack_from("<ff", msg.data)


def test_python_can_host_with_minimal_frames_arms_drives_and_clears(drivers_port):
    bus = open_bus("udp_multicast", GROUP, port=drivers_port)
    host = MinimalHost(bus, node=1)
    try:
        deadline = time.monotonic() + 60.0        # the plant starts (slowly when loaded)
        while host.state is None:                                # the plant is up
            assert time.monotonic() < deadline, "no heartbeat from the emulated drivers"
            host.listen(0.1)
        host.send(0x00B, struct.pack("<II", 2, 2))              # velocity control, VEL_RAMP
        host.send(0x007, struct.pack("<I", 8))                  # closed loop, 4 bytes
        host.listen(0.5, vel=1.5)
        assert (host.state, host.error) == (8, 0)
        assert host.vel == pytest.approx(1.5, abs=0.05) and host.pos > 0.3
        host.listen(WATCHDOG + 0.4)                              # silent: the watchdog trips
        assert (host.state, host.error) == (1, WATCHDOG_EXPIRED)
        host.send(0x018)                                         # Clear_Errors, no byte
        host.send(0x007, struct.pack("<I", 8))
        host.listen(0.5, vel=-0.5)
        assert (host.state, host.error) == (8, 0)
        assert host.vel == pytest.approx(-0.5, abs=0.05)
    finally:
        bus.shutdown()
