"""Parameters of the controller and of the robot: two settings sections (common.schema).

Scenario files, agent configs and the MAVLink parameters all read these frozen dataclasses;
each field carries its default, unit, doc and bounds. The controller and its symbols are
specified in docs/controller.md (notation of Nguyen & La: K, K_theta, D_max for tracking;
K_ij, a, b, c for the potential).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from common import drivers
from common.schema import ConfigError, parameters, setting, validate

log = logging.getLogger(__name__)


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


@dataclass(frozen=True)
class BrakingMargin:
    """The braking-margin budget (docs/controller.md), all in metres."""

    v_max: float          # m/s, fastest the robot is commanded and can go
    reaction: float       # m, v_max * T_eff
    stopping: float       # m, v_max^2 / (2 a_max)
    budget: float         # m, (b - a) / 2

    @property
    def ok(self) -> bool:
        return self.reaction + self.stopping <= self.budget

    def describe(self) -> str:
        verdict = "within" if self.ok else "EXCEEDS"
        return (f"braking margin: v_max*T_eff + v_max^2/(2 a_max) = {self.reaction:.3f} + "
                f"{self.stopping:.3f} = {self.reaction + self.stopping:.3f} m {verdict} "
                f"(b - a)/2 = {self.budget:.3f} m (v_max = {self.v_max:.2f} m/s)")


def braking_margin(control: ControlParams, robot: RobotParams,
                   data_age: float = 0.0) -> BrakingMargin:
    """Budget check (docs/controller.md): v_max*T_eff + v_max^2/(2 a_max) <= (b - a)/2.

    ``data_age`` [s] is the age of neighbour data that extrapolation does not remove; the
    effective reaction time is ``control.period + data_age + robot.drive_latency``.
    """
    v = min(control.v_max, robot.v_wheel_max)
    reaction = control.period + data_age + robot.drive_latency
    return BrakingMargin(v_max=v, reaction=v * reaction, stopping=v * v / (2.0 * robot.a_max),
                         budget=(control.b - control.a) / 2)


def check_braking_margin(control: ControlParams, robot: RobotParams, data_age: float = 0.0,
                         strict: bool = False) -> BrakingMargin:
    """Warn (or raise :class:`ConfigError` when ``strict``) if the braking margin is broken."""
    margin = braking_margin(control, robot, data_age)
    if not margin.ok:
        if strict:
            raise ConfigError(margin.describe() + "; lower K*D_max or raise the wheel ramp")
        log.warning("%s; collision avoidance is not guaranteed", margin.describe())
    return margin


CONTROL_PARAMS = parameters(ControlParams, "BS_")
"""The controller's gains and limits as runtime parameters (MAVLink PARAM_*): BS_K, ..."""
