"""A robot's periods on file: what it knew and what it did, every period, for replay.

An agent configured with ``record_periods`` (agent.settings) appends one record per period
it runs (agent.period.robot_period): its :class:`agent.period.Inputs`, the
:class:`agent.period.Memory` it carried in, its :class:`agent.params.PeriodParams`, the
:class:`agent.period.PeriodOut` it got, the pairs it keeps active and the wheel set-points it
sent. A replay hands the same inputs to the period again (the batch simulator's compiled
one: firmware_sim.period_replay) and compares, bit for bit.

The file is a stream of MessagePack maps (format in docs/formats.md, "Period logs"): each
record a NamedTuple as the list of its fields, recursively, arrays as lists, floats as
float64, so that every value comes back exactly.
"""
from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any, NamedTuple

import msgpack
import numpy as np

from agent.exchange import Exchange
from agent.formation import Places
from agent.law import LawMemory, Reference
from agent.neighbours import Reports
from agent.params import LawParams, NeighbourModel, PeriodParams
from agent.period import Detections, Inputs, Memory, Own, PeriodOut
from agent.trail import OwnPath

VERSION = 1

# the records of records: which fields hold which NamedTuple
_NESTED: dict[type, dict[str, type]] = {
    Inputs: {"own": Own, "reports": Reports, "detections": Detections, "places": Places,
             "path": OwnPath},
    Memory: {"law": LawMemory, "exchange": Exchange},
    PeriodParams: {"law": LawParams, "model": NeighbourModel},
    PeriodOut: {"memory": Memory, "reference": Reference},
}


class PeriodRecord(NamedTuple):
    """One period of one robot, as logged."""

    inputs: Inputs
    memory: Memory          # carried in
    params: PeriodParams
    out: PeriodOut          # what the period gave
    held: list[int]         # the ids of the pairs it keeps active
    sent: tuple[float, float]   # rev/s, the wheel set-points it commanded (right, left)


def _plain(value: Any) -> Any:
    """``value`` as MessagePack takes it: records and sequences as lists, numbers as
    Python floats, ints and bools."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _record(cls: type, fields: list[Any]) -> Any:
    """The ``cls`` NamedTuple of logged ``fields`` (its records of records rebuilt)."""
    nested = _NESTED.get(cls, {})
    names: tuple[str, ...] = cls._fields          # type: ignore[attr-defined]
    if len(fields) != len(names):
        raise ValueError(f"period log: {cls.__name__} has {len(names)} fields, the record "
                         f"{len(fields)}")
    return cls(*(_record(nested[n], f) if n in nested else f for n, f in zip(names, fields)))


class PeriodLog:
    """Appends a robot's periods to ``path`` (created, or truncated)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._file: IO[bytes] = open(self.path, "wb")       # noqa: SIM115 (closed by close)
        self._packer = msgpack.Packer(use_single_float=False)
        self._file.write(self._packer.pack({"version": VERSION}))

    def write(self, inputs: Inputs, memory: Memory, params: PeriodParams, out: PeriodOut,
              held: list[int], sent: tuple[float, float]) -> None:
        self._file.write(self._packer.pack(_plain([inputs, memory, params, out, held,
                                                   list(sent)])))

    def close(self) -> None:
        self._file.close()


def read_periods(path: str | Path) -> Iterator[PeriodRecord]:
    """The records of the period log at ``path``; a file that is not one, or of another
    version, raises ValueError naming it."""
    with open(path, "rb") as fh:
        unpacker = msgpack.Unpacker(fh, raw=False, strict_map_key=False)
        head = next(unpacker, None)
        if not isinstance(head, dict) or head.get("version") != VERSION:
            raise ValueError(f"{path}: not a period log of version {VERSION} "
                             f"(it starts with {head!r:.60})")
        for item in unpacker:
            inputs, memory, params, out, held, sent = item
            yield PeriodRecord(_record(Inputs, inputs), _record(Memory, memory),
                               _record(PeriodParams, params), _record(PeriodOut, out),
                               list(held), (sent[0], sent[1]))
