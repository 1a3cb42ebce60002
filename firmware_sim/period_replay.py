"""Replay a robot's recorded periods (agent.period_log) through the batch simulator's
compiled period: the same commands, bit for bit, or where not.

Each record's inputs and memory are handed to the period as the batch simulator hands them
(its arrays; its memory through a MEMORY record, firmware_sim.swarm_step; the pairs kept
active as its -1-ended rows) and the compiled robot_period's result is compared with what
the agent got and did: its PeriodOut, the pairs it kept and the set-points it sent.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from agent.formation import Places
from agent.neighbours import Reports
from agent.period import Detections, Inputs
from agent.period_log import PeriodRecord
from agent.trail import OwnPath
from firmware_sim import compiled, swarm_step


@dataclass
class Replay:
    """How a replay went."""

    periods: int = 0
    mismatches: list[str] = field(default_factory=list)   # one line per period that differs


def as_batch(inputs: Inputs) -> Inputs:
    """``inputs`` with the arrays the batch simulator passes: float64 and int64 columns."""
    def f(values) -> np.ndarray:
        return np.ascontiguousarray(values, dtype=np.float64)

    def i(values) -> np.ndarray:
        return np.ascontiguousarray(values, dtype=np.int64)

    r, d, pl, p = inputs.reports, inputs.detections, inputs.places, inputs.path
    return inputs._replace(
        reports=Reports(i(r.robot), f(r.stamp), f(r.x), f(r.y), f(r.theta), f(r.v), f(r.u),
                        i(r.slot), i(r.partner), i(r.other)),
        near=i(inputs.near), detections=Detections(f(d.x), f(d.y), f(d.r), d.n),
        places=Places(f(pl.offsets).reshape(-1, 2), f(pl.motion)),
        path=OwnPath(f(p.t), f(p.x), f(p.y), f(p.walked), p.first, p.n, p.size),
        held=i(list(inputs.held[:inputs.n_held]) + [-1]))


def replay(records: Iterable[PeriodRecord]) -> Replay:
    """Each record through the compiled period (numba: the ``sim`` extra)."""
    k = compiled.kernels()
    done = Replay()
    mem = np.zeros(1, swarm_step.MEMORY)
    for rec in records:
        inputs = as_batch(rec.inputs)
        k.store_memory(mem[0], rec.memory)
        ws = swarm_step.workspace(max(inputs.n_near + inputs.detections.n, 1))
        out = k.robot_period(inputs, k.load_memory(mem[0]), rec.params, ws)
        held = list(ws.held[:out.n_held])
        sent = (out.right, out.left)
        if out != rec.out or held != rec.held or sent != rec.sent:
            done.mismatches.append(
                f"period {done.periods} (t = {rec.inputs.t:.3f} s): compiled {_brief(out)}, "
                f"{held}, {sent}; agent {_brief(rec.out)}, {rec.held}, {rec.sent}")
        done.periods += 1
    return done


def _brief(out) -> str:
    return (f"v {out.v!r} u {out.u!r} mode {out.mode} governed {out.governed!r} "
            f"set-points {out.right!r} {out.left!r}")
