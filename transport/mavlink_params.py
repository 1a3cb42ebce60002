"""A parameter table served over MAVLink's PARAM_* protocol; no I/O here.

The table is injected by the process wiring: a tuple of :class:`common.schema.Param` derived
from a settings section (agent.config.CONTROL_PARAMS: each ControlParams field is one REAL32
parameter ``BS_`` + its name in capitals, in field order). Values are read and written
through the vehicle (transport.mavlink_link.VehicleControl), which validates every write.
"""
from __future__ import annotations

from collections.abc import Sequence

from common.schema import Param

NAME_MAX = 16                                  # MAVLink param_id is char[16]


class ParamTable:
    """The parameters by index (PARAM_REQUEST_READ, PARAM_VALUE) and by name."""

    def __init__(self, params: Sequence[Param]):
        for i, p in enumerate(params):
            if len(p.name) > NAME_MAX:
                raise ValueError(f"MAVLink parameter name {p.name!r} ({p.field}) is longer "
                                 f"than {NAME_MAX} characters; give its field a short name")
            if p.index != i:
                raise ValueError(f"parameter {p.name} has index {p.index}, expected {i}")
        self.params = tuple(params)
        self._by_name = {p.name: p for p in self.params}

    def __len__(self) -> int:
        return len(self.params)

    def find(self, name: str = "", index: int = -1) -> Param | None:
        """The parameter at ``index`` when it is >= 0 (PARAM_REQUEST_READ rule), else by
        name."""
        if index >= 0:
            return self.params[index] if index < len(self.params) else None
        return self._by_name.get(name)
