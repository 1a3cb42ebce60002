"""Bus selection, the interface-local-only rule for udp_multicast, and the echo filter."""
import socket
import uuid
from contextlib import ExitStack

import can
import pytest

from transport.can_bus import (DEFAULT_GROUP, DEFAULT_PORT, BusConfig, BusOpenError,
                               EchoFilteredBus, Interface, multicast_hop_limit, open_bus,
                               resolve, socketcan_available)

NO_SOCKETCAN = not socketcan_available("vcan0")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as s:
        s.bind(("::1", 0))
        return s.getsockname()[1]


def data_frame(fid: int = 0x02D, data: bytes = bytes(8)) -> can.Message:
    return can.Message(arbitration_id=fid, data=data, is_extended_id=False)


@pytest.fixture
def buses():
    """Opens buses and shuts every one down, also when the test fails."""
    with ExitStack() as stack:
        def opener(config: BusConfig) -> can.BusABC:
            bus = open_bus(config)
            stack.callback(bus.shutdown)
            return bus
        yield opener


def udp(group: str, port: int) -> BusConfig:
    return BusConfig(Interface.UDP_MULTICAST, group, port)


@pytest.mark.parametrize("kwargs, field", [
    (dict(interface="socketcan"), "interface"),
    (dict(interface=Interface.VIRTUAL, channel=""), "channel"),
    (dict(interface=Interface.UDP_MULTICAST, channel="ff11::1", port=0), "port"),
    (dict(interface=Interface.SOCKETCAN, channel="vcan0", port=43100), "port"),
    (dict(interface=Interface.UDP_MULTICAST, channel="vcan0"), "channel"),
])
def test_config_errors_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        BusConfig(**kwargs)


def test_options_in_python_can_terms():
    assert BusConfig.from_options("udp_multicast", "ff11::b5:4", 43200) == BusConfig(
        Interface.UDP_MULTICAST, "ff11::b5:4", 43200)
    with pytest.raises(ValueError, match="^interface: .*'slcan'"):
        BusConfig.from_options("slcan", "ttyACM0")


@pytest.mark.parametrize("group", ["ff02::1", "ff05::1:3", "ff15::1", "ff01::1", "ff12::b5:1",
                                   "::1", "fe80::1", "239.1.1.1", "224.0.0.1"])
def test_only_interface_local_groups_are_accepted(group):
    with pytest.raises(ValueError, match="^channel:"):
        udp(group, 43100)
    with pytest.raises(BusOpenError, match=f"interface 'auto' channel '{group}'.*channel:"):
        open_bus(BusConfig(Interface.AUTO, group))      # auto falls back to the same check


def test_udp_multicast_hears_its_peer_but_not_itself_and_never_routes(buses):
    port = free_udp_port()
    a, b = buses(udp("ff11::b5:9", port)), buses(udp("ff11::b5:9", port))
    assert isinstance(a, EchoFilteredBus) and multicast_hop_limit(a.inner) == 0
    assert "ff11::b5:9" in a.channel_info and str(port) in a.channel_info
    a.send(data_frame(0x02D, bytes.fromhex("0000 20C0 0000 803E")))
    a.send(can.Message(arbitration_id=0x029, is_remote_frame=True, dlc=8, is_extended_id=False))
    got = [b.recv(2.0), b.recv(2.0)]
    assert [m.arbitration_id for m in got] == [0x02D, 0x029]
    assert bytes(got[0].data) == bytes.fromhex("0000 20C0 0000 803E") and got[1].is_remote_frame
    assert a.recv(0.2) is None and a.echoes_dropped == 2
    b.send(data_frame(0x021))
    assert a.recv(2.0).arbitration_id == 0x021 and b.recv(0.1) is None


def test_robot_buses_on_different_ports_do_not_cross_talk(buses):
    p1, p2 = free_udp_port(), free_udp_port()
    a, b = buses(udp(DEFAULT_GROUP, p1)), buses(udp(DEFAULT_GROUP, p2))
    a.send(data_frame())
    assert b.recv(0.3) is None


def test_a_datagram_that_is_not_a_frame_is_dropped_and_counted(buses):
    port = free_udp_port()
    bus = buses(udp("ff11::b5:8", port))
    with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as raw:
        raw.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, 0)
        raw.sendto(b"\xc1 not msgpack", ("ff11::b5:8", port))
    peer = buses(udp("ff11::b5:8", port))
    peer.send(data_frame(0x009))
    assert bus.recv(2.0).arbitration_id == 0x009
    assert bus.malformed_dropped == 1


def test_echo_filter_on_a_bus_that_echoes_everything():
    """The filter's logic, deterministic: a virtual bus that receives its own frames."""
    now = [0.0]
    channel = str(uuid.uuid4())
    inner = can.Bus(interface="virtual", channel=channel, receive_own_messages=True)
    peer = can.Bus(interface="virtual", channel=channel)
    bus = EchoFilteredBus(inner, "test", horizon_s=0.5, clock=lambda: now[0])
    try:
        bus.send(data_frame(0x00D, bytes(8)))
        peer.send(data_frame(0x00D, bytes(8)))       # the same frame, from someone else
        bus.send(data_frame(0x00D, bytes(7) + b"\x01"))
        got = [bus.recv(0.0) for _ in range(3)]
        assert got[0] is not None and got[1:] == [None, None]
        assert bytes(got[0].data) == bytes(8) and bus.echoes_dropped == 2
        bus.send(data_frame(0x007))
        now[0] = 1.0                                  # echo later than the horizon:
        late = bus.recv(0.0)                          # no longer taken for ours
        assert late is not None and late.arbitration_id == 0x007 and bus.echoes_dropped == 2
    finally:
        bus.shutdown()
        peer.shutdown()


def test_virtual_bus_opens_by_name(buses):
    a = buses(BusConfig(Interface.VIRTUAL, "unit-test-bus"))
    b = buses(BusConfig(Interface.VIRTUAL, "unit-test-bus"))
    a.send(data_frame())
    assert b.recv(0.0).arbitration_id == 0x02D


@pytest.mark.skipif(not NO_SOCKETCAN, reason="this kernel has SocketCAN and vcan0")
def test_socketcan_without_kernel_support_is_a_clear_error():
    with pytest.raises(BusOpenError) as err:
        open_bus(BusConfig(Interface.SOCKETCAN, "vcan0"))
    assert "interface 'socketcan' channel 'vcan0'" in str(err.value)
    assert "no SocketCAN" in str(err.value)


@pytest.mark.skipif(not NO_SOCKETCAN, reason="this kernel has SocketCAN and vcan0")
def test_auto_falls_back_to_one_udp_port_per_robot_bus(buses):
    assert resolve(BusConfig(Interface.AUTO, "vcan3")) == udp(DEFAULT_GROUP, DEFAULT_PORT + 3)
    assert resolve(BusConfig(Interface.AUTO, "can0", port=45000)) == udp(DEFAULT_GROUP, 45000)
    assert resolve(BusConfig(Interface.AUTO, "ff11::7", port=45001)) == udp("ff11::7", 45001)
    port = free_udp_port()
    bus = buses(BusConfig(Interface.AUTO, "vcan0", port=port))
    assert isinstance(bus, EchoFilteredBus) and str(port) in bus.channel_info


def test_a_bus_python_can_cannot_open_is_a_clear_error(monkeypatch):
    def refuse(**kwargs):
        raise can.CanInitializationError("could not connect to a multicast IP network")
    monkeypatch.setattr(can, "Bus", refuse)
    with pytest.raises(BusOpenError) as err:
        open_bus(udp("ff11::b5:1", 43111))
    assert str(err.value).startswith(
        "cannot open CAN bus (interface 'udp_multicast' channel 'ff11::b5:1' port 43111): "
        "could not connect")
