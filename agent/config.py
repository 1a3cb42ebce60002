"""Parameters of the controller and of the robot: two settings sections (common.schema).

Scenario files, agent configs and the MAVLink parameters all read these frozen dataclasses;
each field carries its default, unit, doc and bounds. The controller and its symbols are
specified in docs/controller.md (notation of Nguyen & La: K, K_theta, D_max for tracking;
K_ij, a, b, c for the potential).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from common import drivers
from common.schema import ConfigError, parameters, setting, validate


def _param(default: float, unit: str, doc: str, open_lo: bool = True, param: str | None = None,
           read_only: str | None = None) -> float:
    """A float setting bounded below by 0 (excluded when ``open_lo``)."""
    value: float = setting(default, unit=unit, doc=doc, lo=0.0, open_lo=open_lo, param=param,
                           read_only=read_only)
    return value


@dataclass(frozen=True)
class ControlParams:
    """Gains and limits of the bounded formation controller (paper notation)."""

    K: float = _param(4.0, "1/s", "translational gain: v = K cos(e_theta) min(D_max, D)")
    K_theta: float = _param(3.0, "1/s", "heading gain: u = -K_theta e_theta (+ feed-forward)")
    D_max: float = _param(3.0, "m", "error saturation: |v| <= K * D_max")
    K_ij: float = _param(3.0, "1", "potential gain: V_ij = K_ij ln cosh(r_ij - c)")
    a: float = _param(1.0, "m", "collision distance (no two robots closer than a)")
    b: float = _param(2.0, "m", "avoidance distance (AVOID below b)")
    c: float = _param(4.0, "m", "potential centre; obstacles within c may trigger ROTATE")
    period: float = _param(0.02, "s", "control period T", read_only=(
        "read-only at runtime: the loop period is fixed when the agent starts (set [control] "
        "period in the agent config)"))
    u_max: float = _param(3.0 * math.pi, "rad/s", "clip of the angular speed |u|")
    hysteresis: float = _param(0.5, "m", "leave neighbour-AVOID only beyond b + hysteresis",
                               open_lo=False, param="HYST")
    governor: bool = setting(True, doc="the safety governor limits the speed so that the "
                             "robot can stop before every hazard (false: the law alone, for "
                             "comparisons)")
    sidestep: bool = setting(True, doc="in TRACK, a neighbour nearer than c on the way to "
                             "the reference is passed on its right, b + hysteresis off "
                             "(false: the paper's TRACK, which drives at it and waits for "
                             "AVOID or the governor)")
    pair_hysteresis: bool = setting(False, doc="AVOID's hysteresis per pair: a neighbour "
                                    "stays avoided until it is farther than b + hysteresis "
                                    "(false: per robot, every neighbour within b + "
                                    "hysteresis while the robot avoids any)")
    exchange: float = _param(1.0, "m^2", "two robots swap their places in the formation "
                             "when the sum of their squared distances to them falls by more "
                             "than this (0: every robot keeps its place)", open_lo=False)
    law: str = setting("boundswarm", choices=("boundswarm", "paper"),
                       doc="boundswarm: with the deadlock resolution (sidestep, per-pair "
                       "hysteresis, place exchange, as set); paper: the paper's law with "
                       "its fixes, all three off")

    def __post_init__(self) -> None:
        validate(self)
        if not self.a < self.b < self.c:
            raise ConfigError(f"ControlParams: need 0 < a < b < c, got a={self.a}, b={self.b}, "
                              f"c={self.c}")
        bound = self.period_bound
        if self.period > bound:
            raise ConfigError(
                f"ControlParams.period: period {self.period:g} s breaks the bound "
                f"T <= (b - a)/(2 K D_max) "
                f"= ({self.b:g} - {self.a:g})/(2*{self.K:g}*{self.D_max:g}) = {bound:.4f} s; "
                f"shorten the period or lower K*D_max")

    @property
    def period_bound(self) -> float:
        """Largest period [s] for which one step cannot close the gap b - a: (b-a)/(2 K D_max)."""
        return (self.b - self.a) / (2.0 * self.K * self.D_max)

    @property
    def v_max(self) -> float:
        """Largest commanded translational speed [m/s], K * D_max."""
        return self.K * self.D_max


@dataclass(frozen=True)
class RobotParams:
    """Differential-drive geometry and wheel-driver limits of one robot (SITL defaults)."""

    wheel_radius: float = _param(0.2, "m", "wheel radius r_w")
    wheel_base: float = _param(0.8, "m", "distance between the wheels L")
    wheel_speed_limit: float = _param(drivers.SPEED_LIMIT, "rev/s",
                                      "driver velocity limit per wheel")
    wheel_ramp: float = _param(drivers.RAMP, "rev/s^2", "driver velocity ramp rate (VEL_RAMP)")
    drive_latency: float = _param(0.0, "s", "from a command leaving the computer to the "
                                  "drivers applying it (CAN, driver loop)", open_lo=False)
    watchdog_timeout: float = setting(
        drivers.WATCHDOG, unit="s", lo=0.0, open_lo=True, hi=drivers.WATCHDOG_MAX,
        doc="the drivers' watchdog (ODrive axis.config.watchdog_timeout, with "
            "enable_watchdog = True): a wheel goes on with its last command this long "
            "after the last CAN frame to its driver, then idles")
    speed_up: float = setting(
        0.0, unit="m/s^2", lo=0.0,
        doc="the most the law speeds the robot up, below what its wheels can: its speed "
            "and each wheel's share of its turn grow by at most this (braking still takes "
            "the full ramp). Its neighbours count on it when its data is old, so a swarm "
            "sets it alike on every robot (0: the wheels' ramp)")
    turn_up: float = setting(
        0.0, unit="rad/s^2", lo=0.0,
        doc="the most the law speeds up the robot's turn rate, below what its speed-up "
            "allows (2 speed_up / wheel_base): its wheels' half difference grows by at "
            "most this times half the wheel base (turning slower takes the full ramp). "
            "Its neighbours count on it when its data is old, so a swarm sets it alike on "
            "every robot (0: by speed_up)")
    wheel_slip: float = setting(
        0.0, unit="1", lo=0.0, hi=0.5,
        doc="the most a wheel may slip (the fraction of its turn that does not move the "
            "ground) as the safety governor allows for: unequal slip makes a robot turning "
            "on the spot drift along its heading, so it keeps room for that drift near "
            "hazards and turns slower as the room shrinks (0: wheels that never slip)")

    def __post_init__(self) -> None:
        validate(self)

    @property
    def v_wheel_max(self) -> float:
        """Largest translational speed [m/s] the wheels allow: 2 pi r_w * speed limit."""
        return 2.0 * math.pi * self.wheel_radius * self.wheel_speed_limit

    @property
    def a_max(self) -> float:
        """Largest translational acceleration [m/s^2] the wheel ramp allows."""
        return 2.0 * math.pi * self.wheel_radius * self.wheel_ramp

    @property
    def a_up(self) -> float:
        """Largest acceleration [m/s^2] the law speeds the robot up by (``speed_up``, at
        most :attr:`a_max`)."""
        return min(self.speed_up, self.a_max) if self.speed_up > 0.0 else self.a_max

    @property
    def a_turn_up(self) -> float:
        """Largest acceleration [m/s^2] the law speeds up the wheels' half difference by
        (``turn_up`` times half the wheel base, at most :attr:`a_up`)."""
        up = self.a_up
        return min(0.5 * self.turn_up * self.wheel_base, up) if self.turn_up > 0.0 else up


CONTROL_PARAMS = parameters(ControlParams, "BS_")
"""The controller's gains and limits as runtime parameters (MAVLink PARAM_*): BS_K, ..."""
