"""The agent process's configuration file (TOML), validated once at start-up.

::

    robot_id = 1                    # 1..255 (also the MAVLink system id)
    swarm = "paper"                 # Zenoh key prefix boundswarm/<swarm>
    initial_pose = [x, y, theta]    # m, m, rad: where odometry starts
    autostart = true                # arm and follow the mission without a ground station
    realtime_priority = 0           # 1..99: the loop thread runs SCHED_FIFO at it, Zenoh's
                                    # threads one below (0: normal scheduling)
    align_ticks = true              # ticks at UNIX times n * period + tick_phase
    tick_phase = 0.0                # s, 0 <= tick_phase < [control] period
    [control]                       # agent.config.ControlParams (period = loop period)
    [robot]                         # agent.config.RobotParams (wheels, driver limits)
    [can]                           # transport.settings.CanSettings
    [zenoh]                         # transport.settings.ZenohSettings
    [mavlink]                       # transport.settings.MavlinkSettings
    [timeouts]                      # TimeoutSettings: feedback, staleness, arm
    [sensing]                       # SensingSettings: range
    [pose]                          # agent.pose.PoseSettings, optional: fixes from motion
                                    # capture fused with odometry (absent: odometry alone)
    [impairment]                    # SIMULATION ONLY, written by `boundswarm sitl`:
                                    # agent.impairment.ImpairmentSettings; refused unless
                                    # the CAN bus is emulated (udp_multicast, virtual, vcan*)

Every section is a frozen dataclass of the schema (common.schema), which reads, validates and
writes the file (``to_toml``); every problem raises :class:`common.schema.ConfigError` naming
the file and the field.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

from agent.config import ControlParams, RobotParams
from agent.impairment import ImpairmentSettings
from agent.pose import PoseSettings
from agent.progress import WINDOW
from common.schema import ConfigError, from_table, load_toml, section, setting, validate
from transport.settings import CanSettings, MavlinkSettings, ZenohSettings


@dataclass(frozen=True)
class TimeoutSettings:
    """How long the agent waits for its drivers and trusts its neighbours."""

    feedback: float = setting(0.2, unit="s", doc="without encoder estimates: zero velocity, "
                              "HOLD, CRITICAL", lo=0.0, open_lo=True)
    staleness: float = setting(0.5, unit="s", doc="a neighbour older than this is a static "
                               "obstacle at its last position", lo=0.0, open_lo=True)
    arm: float = setting(5.0, unit="s", doc="for both drivers to enter closed loop after "
                         "arming", lo=0.0, open_lo=True)
    deadlock: float = setting(WINDOW, unit="s", doc="out of tolerance and less than 0.5 m "
                              "closer to the reference over this long: deadlocked (reported, "
                              "STATUSTEXT WARNING)", lo=0.0, open_lo=True)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class SensingSettings:
    """What the agent takes into account around it."""

    range: float | None = setting(None, unit="m", doc="neighbours and obstacles within this "
                                  "distance (absent: 2 c)", lo=0.0, open_lo=True)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class AgentSettings:
    """One robot's agent: identity, start pose and every section."""

    robot_id: int = setting(doc="robot id, also the MAVLink system id", lo=1, hi=255)
    swarm: str = setting(doc="swarm name: Zenoh key prefix boundswarm/<swarm>")
    initial_pose: tuple[float, float, float] = setting(
        unit="m, m, rad", doc="where odometry starts: x, y, theta")
    autostart: bool = setting(False, doc="arm and follow the mission without a ground station")
    realtime_priority: int = setting(0, doc="SCHED_FIFO priority of the loop thread, Zenoh's "
                                     "threads one below (0: normal scheduling)", lo=0, hi=99)
    align_ticks: bool = setting(True, doc="the loop ticks at UNIX times n * period + "
                                "tick_phase, so robots with synchronised clocks tick together "
                                "and their states reach the network as one burst (false: at "
                                "the phase of the agent's start)")
    tick_phase: float = setting(0.0, unit="s", doc="the ticks' offset from multiples of the "
                                "period (below the period; with align_ticks)", lo=0.0)
    record_periods: str | None = setting(None, doc="a file to record every period the agent "
                                         "runs to, what it knew and what it did, for replay "
                                         "(agent.period_log; absent: none)")
    control: ControlParams = section(ControlParams, "controller gains and limits")
    robot: RobotParams = section(RobotParams, "wheels and driver limits")
    can: CanSettings = section(CanSettings, "the robot's CAN bus")
    zenoh: ZenohSettings = section(ZenohSettings, "the Zenoh session")
    timeouts: TimeoutSettings = section(TimeoutSettings, "timeouts")
    sensing: SensingSettings = section(SensingSettings, "sensing")
    mavlink: MavlinkSettings = section(MavlinkSettings, "the MAVLink link")
    pose: PoseSettings | None = section(
        PoseSettings, "an external pose source (motion capture) fused with odometry",
        optional=True)
    impairment: ImpairmentSettings | None = section(
        ImpairmentSettings, "SIMULATION ONLY: impaired neighbour link (boundswarm sitl)",
        optional=True)

    def __post_init__(self) -> None:
        validate(self)
        if self.impairment is not None and not emulated_can(self.can):
            raise ConfigError(f"[impairment] is for simulation only (boundswarm sitl writes "
                              f"it): refused with the CAN bus {self.can.interface} "
                              f"{self.can.channel}, which is not an emulated one "
                              f"(udp_multicast, virtual, socketcan vcan*)")
        if self.sensing.range is None:          # fixed at start: 2 c of the config's control
            object.__setattr__(self, "sensing", SensingSettings(2.0 * self.control.c))
        if any(ch in self.swarm for ch in "/*$?#"):
            raise ConfigError(f"AgentSettings.swarm: must not contain / * $ ? #, "
                              f"got {self.swarm!r}")
        if self.tick_phase >= self.control.period:
            raise ConfigError(f"tick_phase: must be below the period ({self.control.period:g} "
                              f"s), got {self.tick_phase:g}")
        if self.timeouts.feedback < 2 * self.control.period:
            raise ConfigError(f"[timeouts] feedback: must be at least two periods "
                              f"({2 * self.control.period:g} s), got {self.timeouts.feedback:g}")
        if problem := near_radius_problem(self.zenoh.near_radius, self.sensing_range):
            raise ConfigError(f"[zenoh] near_radius: {problem}")

    @property
    def sensing_range(self) -> float:
        """Neighbours and obstacles within this distance [m] count ([sensing] range, 2 c of
        the configured controller when absent)."""
        r = self.sensing.range
        return r if r is not None else 2.0 * self.control.c


def emulated_can(can: CanSettings) -> bool:
    """Whether ``can`` is a bus that only emulated drivers are on (the SITL's): udp_multicast,
    python-can's virtual bus or a SocketCAN vcan interface."""
    return can.interface in ("udp_multicast", "virtual") or (
        can.interface == "socketcan" and can.channel.startswith("vcan"))


def near_radius_problem(near_radius: float, sensing_range: float) -> str | None:
    """Why ``near_radius`` [m] is not usable with ``sensing_range`` [m], or None."""
    if near_radius == 0 or (math.isfinite(near_radius) and near_radius >= sensing_range + 1.0):
        return None
    return (f"must be 0 or at least the sensing range + 1 m ({sensing_range + 1.0:g} m; "
            f"0: every robot at full rate), got {near_radius:g}")


def load_settings(path: str | Path) -> AgentSettings:
    """Read a config file; a relative ``[zenoh] config`` or ``[mavlink] signing_key_file`` is
    taken from the file's folder."""
    path = Path(path)
    s = from_table(AgentSettings, load_toml(path, "agent config"), str(path))
    if s.zenoh.config is not None:
        zpath = path.parent / s.zenoh.config
        if not zpath.is_file():
            raise ConfigError(f"{path}: [zenoh] config: no such file {zpath}")
        s = dataclasses.replace(s, zenoh=dataclasses.replace(s.zenoh, config=str(zpath)))
    if s.mavlink.signing_key_file is not None:
        kpath = path.parent / s.mavlink.signing_key_file
        if not kpath.is_file():
            raise ConfigError(f"{path}: [mavlink] signing_key_file: no such file {kpath}")
        s = dataclasses.replace(s, mavlink=dataclasses.replace(s.mavlink,
                                                               signing_key_file=str(kpath)))
    return s
