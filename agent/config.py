"""Parameters of the controller and of the robot, with their defaults, units and bounds.

This is the one config schema of the project: scenario files, agent configs and (later)
MAVLink parameters are all read through these frozen dataclasses. Each field carries its unit
and its allowed range in ``metadata``; :func:`from_table` builds an instance from a TOML table
and refuses unknown keys, wrong types and out-of-range values with a message naming the field.

Notation follows Nguyen & La: K, K_theta, D_max (tracking), K_ij, a, b, c (potential).
"""
from __future__ import annotations

import dataclasses
import logging
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

log = logging.getLogger(__name__)


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


def _param(default: float, unit: str, doc: str, lo: float | None = 0.0, hi: float | None = None,
           open_lo: bool = True) -> Any:
    """A float field with unit, doc and bounds (``lo < x`` when ``open_lo`` else ``lo <= x``)."""
    return field(default=default, metadata={"unit": unit, "doc": doc, "lo": lo, "hi": hi,
                                            "open_lo": open_lo})


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
    period: float = _param(0.02, "s", "control period T")
    u_max: float = _param(3.0 * math.pi, "rad/s", "clip of the angular speed |u|")
    hysteresis: float = _param(0.5, "m", "leave neighbour-AVOID only beyond b + hysteresis",
                               open_lo=False)

    def __post_init__(self) -> None:
        _check_bounds(self)
        if not self.a < self.b < self.c:
            raise ConfigError(f"control: need 0 < a < b < c, got a={self.a}, b={self.b}, "
                              f"c={self.c}")
        bound = self.period_bound
        if self.period > bound:
            raise ConfigError(
                f"control: period {self.period:g} s breaks the bound T <= (b - a)/(2 K D_max) "
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
    wheel_speed_limit: float = _param(10.0, "rev/s", "driver velocity limit per wheel")
    wheel_ramp: float = _param(1000.0, "rev/s^2", "driver velocity ramp rate (VEL_RAMP)")

    def __post_init__(self) -> None:
        _check_bounds(self)

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
    """The braking-margin budget of DESIGN.md, all in metres."""

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
    """Budget check of DESIGN.md: v_max*T_eff + v_max^2/(2 a_max) <= (b - a)/2.

    ``data_age`` [s] is the age of neighbour data that extrapolation does not remove; the
    effective reaction time is ``control.period + data_age``.
    """
    v = min(control.v_max, robot.v_wheel_max)
    return BrakingMargin(v_max=v, reaction=v * (control.period + data_age),
                         stopping=v * v / (2.0 * robot.a_max), budget=(control.b - control.a) / 2)


def check_braking_margin(control: ControlParams, robot: RobotParams, data_age: float = 0.0,
                         strict: bool = False) -> BrakingMargin:
    """Warn (or raise :class:`ConfigError` when ``strict``) if the braking margin is broken."""
    margin = braking_margin(control, robot, data_age)
    if not margin.ok:
        if strict:
            raise ConfigError(margin.describe() + "; lower K*D_max or raise the wheel ramp")
        log.warning("%s; collision avoidance is not guaranteed", margin.describe())
    return margin


T = TypeVar("T")


def load_toml(path: Path, what: str, error: type[ValueError] = ConfigError) -> dict:
    """Read a TOML file; unreadable or invalid files raise ``error`` naming the path."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{path}: cannot read {what}: {exc.strerror}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None


class TableReader:
    """Typed access to TOML values with messages that name the file and the field."""

    def __init__(self, where: str, error: type[ValueError] = ConfigError):
        self.where, self.error = where, error

    def fail(self, field: str, msg: str) -> ValueError:
        return self.error(f"{self.where}: {field}: {msg}")

    def string(self, table: dict, key: str, field: str, default: str | None = None) -> str:
        value = table.get(key, default)
        if not isinstance(value, str) or not value:
            raise self.fail(field, "missing" if value is None
                            else f"expected a non-empty string, got {value!r}")
        return value

    def integer(self, table: dict, key: str, field: str, default: int | None = None,
                lo: int | None = None, hi: int | None = None) -> int:
        value = table.get(key, default)
        if value is None:
            raise self.fail(field, "missing")
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(field, f"expected an integer, got {value!r}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(field, f"must be in [{lo}, {hi}], got {value}")
        return value

    def strings(self, table: dict, key: str, field: str, default: tuple = ()) -> tuple:
        value = table.get(key, list(default))
        if not isinstance(value, list) or not all(isinstance(x, str) and x for x in value):
            raise self.fail(field, f"expected a list of strings, got {value!r}")
        return tuple(value)

    def number(self, table: dict, key: str, field: str, default: float | None = None,
               positive: bool = False) -> float:
        if key not in table:
            if default is None:
                raise self.fail(field, "missing")
            return default
        value = table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise self.fail(field, f"expected a finite number, got {value!r}")
        if positive and value <= 0:
            raise self.fail(field, f"must be > 0, got {value!r}")
        return float(value)

    def vector(self, table: dict, key: str, field: str, size: int,
               default: tuple | None = None) -> tuple[float, ...]:
        if key not in table:
            if default is None:
                raise self.fail(field, "missing")
            return default
        value = table[key]
        if not isinstance(value, list) or len(value) != size or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in value):
            raise self.fail(field, f"expected a list of {size} finite numbers, got {value!r}")
        return tuple(float(x) for x in value)

    def table(self, doc: dict, key: str) -> dict:
        value = doc.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(f"[{key}]", f"expected a table, got {value!r}")
        return value

    def array_of_tables(self, doc: dict, key: str, required: bool) -> list[dict]:
        value = doc.get(key, [])
        if not isinstance(value, list) or not all(isinstance(x, dict) for x in value):
            raise self.fail(f"[[{key}]]", "expected an array of tables")
        if required and not value:
            raise self.fail(f"[[{key}]]", "missing: at least one entry is required")
        return value

    def only(self, table: dict, allowed: set[str], field: str) -> None:
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise self.fail(field, f"unknown field(s) {', '.join(unknown)}; "
                                   f"allowed: {', '.join(sorted(allowed))}")



def _check_bounds(obj: Any) -> None:
    name = type(obj).__name__
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ConfigError(f"{name}.{f.name}: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(f"{name}.{f.name}: must be finite, got {value!r}")
        lo, hi = f.metadata.get("lo"), f.metadata.get("hi")
        if lo is not None and (value < lo or (f.metadata.get("open_lo") and value == lo)):
            rel = ">" if f.metadata.get("open_lo") else ">="
            raise ConfigError(f"{name}.{f.name}: must be {rel} {lo:g} "
                              f"[{f.metadata['unit']}], got {value!r}")
        if hi is not None and value > hi:
            raise ConfigError(f"{name}.{f.name}: must be <= {hi:g}, got {value!r}")


def from_table(cls: type[T], table: Mapping[str, Any], where: str) -> T:
    """Build ``cls`` from a TOML table; unknown keys and bad values raise :class:`ConfigError`.

    ``where`` names the place for the message, e.g. ``"scenarios/paper.toml [control]"``.
    """
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - names)
    if unknown:
        raise ConfigError(f"{where}: unknown field(s) {', '.join(unknown)}; "
                          f"allowed: {', '.join(sorted(names))}")
    values: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: field '{key}' must be a number, got {value!r}")
        values[key] = float(value)
    try:
        return cls(**values)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def describe_fields(cls: type) -> list[tuple[str, Any, str, str]]:
    """(name, default, unit, doc) of each field, for documentation and parameter lists."""
    return [(f.name, f.default, f.metadata["unit"], f.metadata["doc"])
            for f in dataclasses.fields(cls)]
