"""Bus selection, the echo filter of udp_multicast, and two processes on one robot bus."""
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest
from helpers import free_port

from transport.canbus import DEFAULT_GROUP, BusOpenError, EchoFilteredBus, has_socketcan, open_bus
from transport.wheel_drivers import WheelDrivers

ROOT = Path(__file__).resolve().parent.parent


def test_udp_multicast_hears_peers_but_not_itself():
    port = free_port("udp6")
    a = open_bus("udp_multicast", "ff11::b5:9", port=port)
    b = open_bus("udp_multicast", "ff11::b5:9", port=port)
    # a python-can tool on the same bus (e.g. can.viewer): it hears both and is heard
    tool = can.Bus(interface="udp_multicast", channel="ff11::b5:9", port=port, hop_limit=0)
    try:
        assert isinstance(a, EchoFilteredBus) and isinstance(b, EchoFilteredBus)
        sent_at = time.time()
        a.send(can.Message(arbitration_id=0x02D, data=bytes(8), is_extended_id=False))
        got = b.recv(2.0)
        assert got is not None and got.arbitration_id == 0x02D
        assert sent_at - 0.5 < got.timestamp < time.time() + 0.5   # the kernel's receive time
        waited = time.monotonic()
        assert a.recv(0.3) is None                  # its own frame never reaches it
        assert time.monotonic() - waited >= 0.29    # and it waited for the timeout
        got = tool.recv(2.0)
        assert got is not None and got.arbitration_id == 0x02D
        tool.send(can.Message(arbitration_id=0x029, data=bytes(8), is_extended_id=False))
        for bus in (a, b):
            got = bus.recv(2.0)
            assert got is not None and got.arbitration_id == 0x029
        b.send(can.Message(arbitration_id=0x04D, data=bytes(8), is_extended_id=False))
        got = a.recv(2.0)
        assert got is not None and got.arbitration_id == 0x04D
        assert b.recv(0.3) is None and a.malformed == b.malformed == 0
    finally:
        a.shutdown()
        b.shutdown()
        tool.shutdown()


def test_groups_that_could_leave_the_host_are_refused():
    # refused by address check before any socket is opened: nothing is ever sent to them
    for group in ("ff15::1", "ff02::1", "239.1.1.1"):
        with pytest.raises(BusOpenError, match="ff11|IPv6 multicast"):
            open_bus("udp_multicast", group, port=free_port("udp6"))


def test_socketcan_missing_is_a_clear_error():
    if has_socketcan("vcan0"):
        pytest.skip("this kernel has vcan0")
    with pytest.raises(BusOpenError, match="'socketcan' channel 'vcan0'.*no SocketCAN"):
        open_bus("socketcan", "vcan0")


def test_auto_falls_back_to_udp_multicast_without_socketcan():
    if has_socketcan("vcan0"):
        pytest.skip("this kernel has vcan0")
    port = free_port("udp6")
    bus = open_bus("auto", "vcan0", port=port)
    peer = open_bus("udp_multicast", DEFAULT_GROUP, port=port)
    try:
        assert isinstance(bus, EchoFilteredBus)
        assert bus.inner._multicast.group == DEFAULT_GROUP and bus.inner._multicast.port == port
        peer.send(can.Message(arbitration_id=0x02D, data=bytes(8), is_extended_id=False))
        got = bus.recv(2.0)
        assert got is not None and got.arbitration_id == 0x02D
    finally:
        bus.shutdown()
        peer.shutdown()


def test_virtual_bus_carries_frames_between_its_users():
    a = open_bus("virtual", "unit-test-channel")
    b = open_bus("virtual", "unit-test-channel")
    try:
        assert not isinstance(a, EchoFilteredBus)
        a.send(can.Message(arbitration_id=0x029, data=bytes(range(8)), is_extended_id=False))
        got = b.recv(1.0)
        assert got is not None and got.arbitration_id == 0x029 and bytes(got.data) == \
            bytes(range(8))
        assert a.recv(0.1) is None                  # not its own frame
    finally:
        a.shutdown()
        b.shutdown()


def test_host_and_drivers_in_two_processes_over_udp_multicast():
    port = free_port("udp6")
    child = subprocess.Popen(
        [sys.executable, "-m", "hil.cli", "plant", "drivers",
         "--can-interface", "udp_multicast", "--can-channel", "ff11::b5:2",
         "--can-port", str(port)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    bus = open_bus("udp_multicast", "ff11::b5:2", port=port)
    try:
        host = WheelDrivers(bus)
        end = time.monotonic() + 15
        while host.feedback() is None and time.monotonic() < end:
            time.sleep(0.02)
        assert host.feedback() is not None, "no feedback from the drivers process"
        host.arm()
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.0:
            host.command(3.0, 3.0)
            time.sleep(0.02)
        fb = host.feedback()
        assert fb is not None
        assert fb.closed_loop and fb.vel_rev_s == pytest.approx((3.0, 3.0), abs=0.01)
        assert fb.age < 0.1
        # stop commanding: the drivers' watchdog trips and the host names it
        time.sleep(0.4)
        fb = host.feedback()
        assert fb is not None
        assert "right: WATCHDOG_TIMER_EXPIRED" in fb.errors
        assert host.ignored.get("dlc", 0) == 0
    finally:
        bus.shutdown()
        child.terminate()
        try:
            child.wait(timeout=10)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
    assert child.stdout is not None
    assert child.returncode in (0, -15), child.stdout.read().decode()


def test_a_stray_datagram_on_the_bus_port_is_skipped_not_fatal():
    port = free_port("udp6")
    bus = open_bus("udp_multicast", "ff11::b5:8", port=port)
    peer = open_bus("udp_multicast", "ff11::b5:8", port=port)
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as s:
            s.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, 0)
            s.sendto(b"not a CAN frame", ("ff11::b5:8", port))
        peer.send(can.Message(arbitration_id=0x02D, data=bytes(8), is_extended_id=False))
        got = bus.recv(2.0)
        assert isinstance(bus, EchoFilteredBus)
        assert got is not None and got.arbitration_id == 0x02D and bus.malformed == 1
    finally:
        bus.shutdown()
        peer.shutdown()


def test_a_send_port_that_is_another_bus_port_neither_blocks_nor_steals_from_it():
    """A bus sends from an ephemeral port, drawn from the range robot buses' ports come
    from: a bus opened later on that port opens and hears all of its peers' frames."""
    opened = [open_bus("udp_multicast", "ff11::b5:6", port=free_port("udp6"))]
    try:
        x = opened[0]
        assert isinstance(x, EchoFilteredBus)
        port = x._tx.getsockname()[1]
        opened.append(y := open_bus("udp_multicast", "ff11::b5:6", port=port))
        opened.append(peer := open_bus("udp_multicast", "ff11::b5:6", port=port))
        for i in range(100):
            peer.send(can.Message(arbitration_id=i, data=bytes(8), is_extended_id=False))
        got: list[int] = []
        while len(got) < 100 and (msg := y.recv(2.0)) is not None:
            got.append(msg.arbitration_id)
        assert got == list(range(100))
        x.send(can.Message(arbitration_id=0x02D, data=bytes(8), is_extended_id=False))
        assert y.recv(0.3) is None                  # another bus: not heard there
    finally:
        for bus in opened:
            bus.shutdown()
