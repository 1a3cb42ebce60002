"""The agent process's configuration file (TOML), validated once at start-up.

::

    robot_id = 1                    # 1..255 (also the MAVLink system id)
    swarm = "paper"                 # Zenoh key prefix boundswarm/<swarm>
    initial_pose = [x, y, theta]    # m, m, rad: where odometry starts
    autostart = true                # arm and follow the mission without a ground station
    realtime_priority = 0           # 1..99: the loop thread runs SCHED_FIFO at it, Zenoh's
                                    # threads one below (0: normal scheduling)
    [control]                       # agent.config.ControlParams (period = loop period)
    [robot]                         # agent.config.RobotParams (wheels, driver limits)
    [can]                           # python-can terms: interface, channel, port (udp_multicast),
                                    # bitrate; left_node, right_node (ODrive node ids)
    [zenoh]                         # mode ("client" or "peer"), connect = [...], listen = [...],
                                    # near_radius (m; 0: full-rate states of every robot)
    [timeouts]                      # feedback (0.2 s), staleness (0.5 s), arm (5 s)
    [sensing]                       # range (m, default 2c)
    [mavlink]                       # url (udpout:127.0.0.1:14550), origin [lat, lon, alt],
                                    # gcs_failsafe, gcs_timeout (1.5 s), signing_key_file

Every problem raises :class:`agent.config.ConfigError` naming the file and the field.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

from agent.config import (ConfigError, ControlParams, RobotParams, TableReader, from_table,
                          load_toml)
from transport.mavlink_io import parse_url

TOP_KEYS = {"robot_id", "swarm", "initial_pose", "autostart", "realtime_priority", "control",
            "robot", "can", "zenoh", "timeouts", "sensing", "mavlink"}


@dataclass(frozen=True)
class CanSettings:
    """Where the robot's motor drivers are, in python-can's own terms."""

    interface: str = "udp_multicast"
    channel: str = "ff11::b5:1"
    port: int | None = None          # udp_multicast only: one port per robot bus
    bitrate: int = 500_000           # bit/s (socketcan interfaces are set up outside)
    left_node: int = 0
    right_node: int = 1


@dataclass(frozen=True)
class ZenohSettings:
    mode: str = "client"
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ()
    config: str | None = None        # a Zenoh JSON5 config file (TLS...); relative to the
                                     # agent config's folder; replaces mode/connect/listen
    near_radius: float = 0.0         # m; > 0: full-rate states only from robots this near,
                                     # beacons from the others (transport.zenoh_link)


@dataclass(frozen=True)
class MavlinkSettings:
    """The ``[mavlink]`` table of the agent config."""

    url: str = "udpout:127.0.0.1:14550"       # see transport.mavlink_io
    origin: tuple[float, float, float] = (-35.363261, 149.16523, 584.0)
    #   geodetic origin of the world frame: latitude [deg], longitude [deg], altitude AMSL [m]
    #   (default: ArduPilot SITL's home, so the usual ground-station setups line up)
    gcs_failsafe: bool = False                # HOLD when no GCS heartbeat for gcs_timeout
    gcs_timeout: float = 1.5                  # s
    signing_key_file: str | None = None       # 32 raw bytes or a passphrase; None: no signing

    def __post_init__(self) -> None:
        lat, lon, alt = self.origin
        if not (math.isfinite(lat) and abs(lat) <= 85.0):
            raise ConfigError(f"mavlink.origin: latitude must be within +-85 deg (the local "
                              f"tangent plane fails near the poles), got {lat!r}")
        if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
            raise ConfigError(f"mavlink.origin: longitude must be in [-180, 180] deg, "
                              f"got {lon!r}")
        if not math.isfinite(alt):
            raise ConfigError(f"mavlink.origin: altitude must be finite [m], got {alt!r}")
        if not (math.isfinite(self.gcs_timeout) and self.gcs_timeout > 0):
            raise ConfigError(f"mavlink.gcs_timeout: must be > 0 [s], got {self.gcs_timeout!r}")
        try:
            parse_url(self.url)
        except ValueError as exc:
            raise ConfigError(f"mavlink.url: {exc}") from None

    @classmethod
    def from_table(cls, table: dict, where: str) -> MavlinkSettings:
        """From a TOML table; errors name ``where`` and the field."""
        rd = TableReader(where)
        rd.only(table, {"url", "origin", "gcs_failsafe", "gcs_timeout", "signing_key_file"},
                "[mavlink]")
        failsafe = table.get("gcs_failsafe", False)
        if not isinstance(failsafe, bool):
            raise rd.fail("[mavlink] gcs_failsafe", f"expected true or false, got {failsafe!r}")
        url = rd.string(table, "url", "[mavlink] url", cls.url)
        origin = rd.vector(table, "origin", "[mavlink] origin", 3, cls.origin)
        timeout = rd.number(table, "gcs_timeout", "[mavlink] gcs_timeout", 1.5, positive=True)
        key = (rd.string(table, "signing_key_file", "[mavlink] signing_key_file")
               if "signing_key_file" in table else None)
        try:
            return cls(url=url, origin=origin, gcs_failsafe=failsafe, gcs_timeout=timeout,
                       signing_key_file=key)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None


@dataclass(frozen=True)
class AgentSettings:
    robot_id: int
    swarm: str
    initial_pose: tuple[float, float, float]
    control: ControlParams = field(default_factory=ControlParams)
    robot: RobotParams = field(default_factory=RobotParams)
    can: CanSettings = field(default_factory=CanSettings)
    zenoh: ZenohSettings = field(default_factory=ZenohSettings)
    autostart: bool = False
    feedback_timeout: float = 0.2     # s without encoder estimates -> zero, HOLD, CRITICAL
    arm_timeout: float = 5.0          # s for both drivers to enter closed loop after arming
    staleness: float = 0.5            # s, neighbour kept as a static obstacle beyond this
    sensing_range: float = 8.0        # m
    mavlink: MavlinkSettings = field(default_factory=MavlinkSettings)
    realtime_priority: int = 0        # SCHED_FIFO priority of the loop thread, Zenoh's one
                                      # below (0: normal)


def near_radius_problem(near_radius: float, sensing_range: float) -> str | None:
    """Why ``near_radius`` [m] is not usable with ``sensing_range`` [m], or None."""
    if near_radius == 0 or (math.isfinite(near_radius) and near_radius >= sensing_range + 1.0):
        return None
    return (f"must be 0 or at least the sensing range + 1 m ({sensing_range + 1.0:g} m; "
            f"0: every robot at full rate), got {near_radius:g}")


def parse_settings(doc: dict, where: str) -> AgentSettings:
    rd = TableReader(where)
    rd.only(doc, TOP_KEYS, "top level")
    control = from_table(ControlParams, rd.table(doc, "control"), f"{where} [control]")
    robot = from_table(RobotParams, rd.table(doc, "robot"), f"{where} [robot]")

    can_t = rd.table(doc, "can")
    rd.only(can_t, {"interface", "channel", "port", "bitrate", "left_node", "right_node"},
            "[can]")
    port = can_t.get("port")
    can = CanSettings(
        interface=rd.string(can_t, "interface", "[can] interface", "udp_multicast"),
        channel=rd.string(can_t, "channel", "[can] channel", CanSettings.channel),
        port=None if port is None else rd.integer(can_t, "port", "[can] port", lo=1, hi=65535),
        bitrate=rd.integer(can_t, "bitrate", "[can] bitrate", 500_000, lo=10_000,
                           hi=1_000_000),
        left_node=rd.integer(can_t, "left_node", "[can] left_node", 0, lo=0, hi=63),
        right_node=rd.integer(can_t, "right_node", "[can] right_node", 1, lo=0, hi=63))
    if can.left_node == can.right_node:
        raise rd.fail("[can] right_node", f"must differ from left_node ({can.left_node})")

    z = rd.table(doc, "zenoh")
    rd.only(z, {"mode", "connect", "listen", "config", "near_radius"}, "[zenoh]")
    zenoh = ZenohSettings(mode=rd.string(z, "mode", "[zenoh] mode", "client"),
                          connect=rd.strings(z, "connect", "[zenoh] connect",
                                             ZenohSettings.connect),
                          listen=rd.strings(z, "listen", "[zenoh] listen"),
                          config=rd.string(z, "config", "[zenoh] config")
                          if "config" in z else None,
                          near_radius=rd.number(z, "near_radius", "[zenoh] near_radius", 0.0))
    if zenoh.mode not in ("client", "peer"):
        raise rd.fail("[zenoh] mode", f"expected client or peer, got {zenoh.mode!r}")
    if zenoh.mode == "client" and not zenoh.connect and zenoh.config is None:
        raise rd.fail("[zenoh] connect", "a client needs at least one router endpoint")

    t = rd.table(doc, "timeouts")
    rd.only(t, {"feedback", "staleness", "arm"}, "[timeouts]")
    arm = rd.number(t, "arm", "[timeouts] arm", 5.0, positive=True)
    feedback = rd.number(t, "feedback", "[timeouts] feedback", 0.2, positive=True)
    staleness = rd.number(t, "staleness", "[timeouts] staleness", 0.5, positive=True)
    if feedback < 2 * control.period:
        raise rd.fail("[timeouts] feedback", f"must be at least two periods "
                                             f"({2 * control.period:g} s), got {feedback:g}")
    s = rd.table(doc, "sensing")
    rd.only(s, {"range"}, "[sensing]")
    sensing = rd.number(s, "range", "[sensing] range", 2.0 * control.c, positive=True)
    if problem := near_radius_problem(zenoh.near_radius, sensing):
        raise rd.fail("[zenoh] near_radius", problem)

    autostart = doc.get("autostart", False)
    if not isinstance(autostart, bool):
        raise rd.fail("autostart", f"expected true or false, got {autostart!r}")
    swarm = rd.string(doc, "swarm", "swarm")
    if any(ch in swarm for ch in "/*$?#"):
        raise rd.fail("swarm", f"must not contain / * $ ? #, got {swarm!r}")
    return AgentSettings(
        robot_id=rd.integer(doc, "robot_id", "robot_id", lo=1, hi=255), swarm=swarm,
        initial_pose=rd.vector(doc, "initial_pose", "initial_pose", 3),
        control=control, robot=robot, can=can, zenoh=zenoh, autostart=autostart,
        feedback_timeout=feedback, staleness=staleness, sensing_range=sensing,
        arm_timeout=arm, mavlink=MavlinkSettings.from_table(rd.table(doc, "mavlink"), where),
        realtime_priority=rd.integer(doc, "realtime_priority", "realtime_priority", 0,
                                     lo=0, hi=99))


def load_settings(path: str | Path) -> AgentSettings:
    """Read a config file; a relative ``[zenoh] config`` is taken from the file's folder."""
    path = Path(path)
    s = parse_settings(load_toml(path, "agent config"), str(path))
    if s.zenoh.config is not None:
        zpath = path.parent / s.zenoh.config
        if not zpath.is_file():
            raise TableReader(str(path)).fail("[zenoh] config", f"no such file {zpath}")
        s = dataclasses.replace(s, zenoh=dataclasses.replace(s.zenoh, config=str(zpath)))
    if s.mavlink.signing_key_file is not None:
        kpath = path.parent / s.mavlink.signing_key_file
        if not kpath.is_file():
            raise TableReader(str(path)).fail("[mavlink] signing_key_file",
                                              f"no such file {kpath}")
        s = dataclasses.replace(s, mavlink=dataclasses.replace(s.mavlink,
                                                               signing_key_file=str(kpath)))
    return s



def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)


def settings_to_toml(s: AgentSettings) -> str:
    """The TOML text of ``s`` (what :func:`load_settings` reads back to an equal object)."""
    lines = [f"robot_id = {s.robot_id}", f"swarm = {_toml_value(s.swarm)}",
             f"initial_pose = {_toml_value(list(s.initial_pose))}",
             f"autostart = {_toml_value(s.autostart)}",
             f"realtime_priority = {s.realtime_priority}"]
    tables = {"control": dataclasses.asdict(s.control), "robot": dataclasses.asdict(s.robot),
              "can": {k: v for k, v in dataclasses.asdict(s.can).items() if v is not None},
              "zenoh": {k: v for k, v in dataclasses.asdict(s.zenoh).items() if v is not None},
              "timeouts": {"feedback": s.feedback_timeout, "staleness": s.staleness,
                           "arm": s.arm_timeout},
              "mavlink": {k: v for k, v in dataclasses.asdict(s.mavlink).items()
                          if v is not None},
              "sensing": {"range": s.sensing_range}}
    for name, table in tables.items():
        lines.append(f"\n[{name}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"
