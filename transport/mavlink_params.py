"""The controller's gains and limits as MAVLink parameters (PARAM_* protocol); no I/O here.

Each field of :class:`agent.config.ControlParams` is one REAL32 parameter, indexed in field
order and named ``BS_`` + the field name in capitals (at most 16 characters)::

    index  name         field       unit
    0      BS_K         K           1/s
    1      BS_K_THETA   K_theta     1/s
    2      BS_D_MAX     D_max       m
    3      BS_K_IJ      K_ij        1
    4      BS_A         a           m
    5      BS_B         b           m
    6      BS_C         c           m
    7      BS_PERIOD    period      s      read-only at runtime
    8      BS_U_MAX     u_max       rad/s
    9      BS_HYST      hysteresis  m

A write is validated by building a new ``ControlParams`` with the one field replaced, so
every rule of the config (bounds, a < b < c, the period bound) applies unchanged; a refused
write leaves the old parameters in force and says why. ``BS_PERIOD`` is refused: the loop
period is fixed when the agent process starts.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from agent.config import ConfigError, ControlParams

PREFIX = "BS_"
NAME_MAX = 16                                  # MAVLink param_id is char[16]
_ABBREVIATIONS = {"hysteresis": "HYST"}        # short names chosen by hand
_READ_ONLY = {"period": "read-only at runtime: the loop period is fixed when the agent "
                        "starts (set [control] period in the agent config)"}


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: its MAVLink name, the ControlParams field, unit and meaning."""

    index: int
    name: str
    field: str
    unit: str
    doc: str
    read_only: str | None          # why it cannot be set, or None when writable


@dataclass(frozen=True)
class SetResult:
    """Outcome of a write: the parameters now in force, and the reason when refused."""

    params: ControlParams
    refused: str | None


def _specs() -> tuple[ParamSpec, ...]:
    specs = []
    for i, f in enumerate(dataclasses.fields(ControlParams)):
        name = PREFIX + _ABBREVIATIONS.get(f.name, f.name.upper())
        if len(name) > NAME_MAX:
            raise ValueError(f"MAVLink parameter name {name!r} for ControlParams.{f.name} is "
                             f"longer than {NAME_MAX} characters; add an abbreviation")
        specs.append(ParamSpec(i, name, f.name, f.metadata["unit"], f.metadata["doc"],
                               _READ_ONLY.get(f.name)))
    return tuple(specs)


PARAMS: tuple[ParamSpec, ...] = _specs()
_BY_NAME = {p.name: p for p in PARAMS}


def find(name: str = "", index: int = -1) -> ParamSpec | None:
    """The parameter at ``index`` when it is >= 0 (PARAM_REQUEST_READ rule), else by name."""
    if index >= 0:
        return PARAMS[index] if index < len(PARAMS) else None
    return _BY_NAME.get(name)


def value(params: ControlParams, spec: ParamSpec) -> float:
    """The current value of ``spec`` in ``params`` (in the unit of the field)."""
    return float(getattr(params, spec.field))


def set_value(params: ControlParams, spec: ParamSpec, new: float) -> SetResult:
    """``params`` with ``spec`` set to ``new``, or the old ``params`` and why not."""
    if spec.read_only is not None:
        return SetResult(params, f"{spec.name} is {spec.read_only}")
    try:
        return SetResult(dataclasses.replace(params, **{spec.field: float(new)}), None)
    except ConfigError as exc:
        return SetResult(params, f"{spec.name} = {new:g} refused: {exc}")
