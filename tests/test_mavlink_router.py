"""The SITL's MAVLink router: agents' datagrams to the ground station unchanged, the ground
station's frames to the agent they target (or to all), on loopback."""
import select
import socket

import pytest
from pymavlink.dialects.v20 import common as mav2

from hil.sitl.mavlink_router import MavlinkRouter

WAIT = 5.0               # s, generous on a shared machine (the router forwards every 10 ms)


class Sender:
    """Encodes MAVLink 2 frames of one system id."""

    def __init__(self, sysid: int):
        self.mav = mav2.MAVLink(None, srcSystem=sysid, srcComponent=1)

    def heartbeat(self) -> bytes:
        return self.mav.heartbeat_encode(mav2.MAV_TYPE_GROUND_ROVER, mav2.MAV_AUTOPILOT_GENERIC,
                                         0, 0, 0).pack(self.mav)

    def arm(self, target: int) -> bytes:
        return self.mav.command_long_encode(target, 1, mav2.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                            1, 0, 0, 0, 0, 0, 0).pack(self.mav)


def udp() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


def received(sock: socket.socket, timeout: float = WAIT) -> bytes | None:
    if not select.select([sock], [], [], timeout)[0]:
        return None
    return sock.recv(65536)


@pytest.fixture
def rig():
    gcs = udp()
    agents = {sid: udp() for sid in (3, 4)}
    router = MavlinkRouter(0, gcs.getsockname()[1]).start()
    try:
        yield router, gcs, agents
    finally:
        router.close()
        gcs.close()
        for s in agents.values():
            s.close()


def test_agents_datagrams_reach_the_ground_station_unchanged(rig):
    router, gcs, agents = rig
    datagram = Sender(3).heartbeat() + Sender(3).heartbeat()       # two frames in one
    agents[3].sendto(datagram, ("127.0.0.1", router.agents_port))
    assert received(gcs) == datagram
    assert router.addresses[3] == agents[3].getsockname()


def test_ground_station_frames_go_to_their_target_or_to_all(rig):
    router, gcs, agents = rig
    for sid, sock in agents.items():                   # the router learns each address
        sock.sendto(Sender(sid).heartbeat(), ("127.0.0.1", router.agents_port))
        assert select.select([gcs], [], [], WAIT)[0]
        _, router_at = gcs.recvfrom(65536)             # where the ground station answers
    gcs_mav = Sender(255)
    arm = gcs_mav.arm(4)
    gcs.sendto(arm, router_at)
    assert received(agents[4]) == arm
    assert received(agents[3], 0.3) is None            # not for robot 3
    beat = gcs_mav.heartbeat()                         # no target: every agent
    gcs.sendto(beat, router_at)
    assert received(agents[3]) == beat and received(agents[4]) == beat
    gcs.sendto(gcs_mav.arm(9), router_at)
    for _ in range(int(WAIT / 0.05)):
        if router.counts["unknown_target"]:
            break
        select.select([], [], [], 0.05)
    assert router.counts["unknown_target"] == 1
