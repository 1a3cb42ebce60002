"""The links' settings sections (common.schema): the robot's CAN bus, its Zenoh session and
its MAVLink link. They are the ``[can]``, ``[zenoh]`` and ``[mavlink]`` tables of the agent
config (agent.settings), and the defaults every launcher takes."""
from __future__ import annotations

from dataclasses import dataclass

from common import drivers
from common.schema import ConfigError, setting, validate
from transport.canbus import DEFAULT_GROUP
from transport.mavlink_io import parse_url


@dataclass(frozen=True)
class CanSettings:
    """Where the robot's motor drivers are, in python-can's own terms."""

    interface: str = setting("udp_multicast", doc="python-can interface (socketcan, "
                             "udp_multicast, virtual, auto)")
    channel: str = setting(DEFAULT_GROUP, doc="python-can channel: a SocketCAN interface or an "
                           "interface-local IPv6 group (udp_multicast)")
    port: int | None = setting(None, doc="udp_multicast only: the UDP port of this robot's bus "
                               "(one per robot)", lo=1, hi=65535)
    bitrate: int = setting(500_000, unit="bit/s", doc="bus bit rate (socketcan interfaces are "
                           "set up outside)", lo=10_000, hi=1_000_000)
    left_node: int = setting(drivers.LEFT_NODE, doc="ODrive node id of the left wheel",
                             lo=0, hi=63)
    right_node: int = setting(drivers.RIGHT_NODE, doc="ODrive node id of the right wheel",
                              lo=0, hi=63)

    def __post_init__(self) -> None:
        validate(self)
        if self.left_node == self.right_node:
            raise ConfigError(f"CanSettings.right_node: must differ from left_node "
                              f"({self.left_node})")


@dataclass(frozen=True)
class ZenohSettings:
    """The agent's Zenoh session (transport.zenoh_link)."""

    mode: str = setting("client", doc="session mode", choices=("client", "peer"))
    connect: tuple[str, ...] = setting(("tcp/127.0.0.1:7447",), doc="endpoints to connect to")
    listen: tuple[str, ...] = setting((), doc="endpoints to listen on")
    config: str | None = setting(None, doc="a Zenoh JSON5 config file (TLS...), relative to the "
                                 "agent config's folder; replaces mode, connect and listen")
    near_radius: float = setting(0.0, unit="m", doc="> 0: full-rate states only from robots "
                                 "this near or closing in to be so, beacons from the others "
                                 "(0: every robot)", lo=0.0)

    def __post_init__(self) -> None:
        validate(self)
        if self.mode == "client" and not self.connect and self.config is None:
            raise ConfigError("ZenohSettings.connect: a client needs at least one router "
                              "endpoint")


@dataclass(frozen=True)
class MavlinkSettings:
    """The agent's MAVLink link to ground stations (transport.mavlink_link)."""

    url: str = setting("udpout:127.0.0.1:14550", doc="transport URL (transport.mavlink_io)")
    origin: tuple[float, float, float] = setting(
        (-35.363261, 149.16523, 584.0), unit="deg, deg, m",
        doc="geodetic origin of the world frame: latitude, longitude, altitude AMSL "
            "(default: ArduPilot SITL's home, so the usual ground-station setups line up)")
    gcs_failsafe: bool = setting(False, doc="HOLD when no ground-station heartbeat for "
                                 "gcs_timeout")
    gcs_timeout: float = setting(1.5, unit="s", doc="ground-station heartbeat timeout",
                                 lo=0.0, open_lo=True)
    signing_key_file: str | None = setting(None, doc="MAVLink signing key: 32 raw bytes or a "
                                           "passphrase (absent: no signing)")

    def __post_init__(self) -> None:
        validate(self)
        lat, lon, _ = self.origin
        if abs(lat) > 85.0:
            raise ConfigError(f"MavlinkSettings.origin: latitude must be within +-85 deg (the "
                              f"local tangent plane fails near the poles), got {lat!r}")
        if not -180.0 <= lon <= 180.0:
            raise ConfigError(f"MavlinkSettings.origin: longitude must be in [-180, 180] deg, "
                              f"got {lon!r}")
        try:
            parse_url(self.url)
        except ValueError as exc:
            raise ConfigError(f"MavlinkSettings.url: {exc}") from None
