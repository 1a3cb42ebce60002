"""SIMULATION ONLY: an impaired link in front of the neighbour states an agent receives.

The SITL (``boundswarm sitl``) gives each agent the link of its scenario's ``[world]``
(docs/world.md "In the SITL") by writing an ``[impairment]`` section into the agents'
configs; nothing else writes one, a config with it is refused unless the robot's CAN bus is
an emulated one (agent.settings), and the agent process logs it loudly at start.

:class:`ImpairedSwarm` decorates a :class:`common.ports.SwarmPort`: each new neighbour state
the link delivers is lost (independently, or in Gilbert-Elliott bursts,
:func:`common.draws.loss_step`), or else held back by link_delay + link_jitter N(0, 1)
(at least 0) from its arrival. Loss and delay are per link (this receiver, that sender),
drawn from the world's seed, this robot's id, the sender's id and the count of the sender's
states taken, with the draws of :mod:`common.draws`. The neighbours it returns are, per
robot, the newest state (by stamp) whose delayed arrival has passed, as the link's own cache
keeps them. Publishing, obstacles and the mission pass through untouched.
"""
from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from common.draws import LINK_AGE, LINK_LOSS, loss_burst_problem, loss_step, normal, uniform
from common.payloads import MissionMsg, ObstaclesMsg, Received, StateMsg
from common.ports import SwarmPort
from common.schema import ConfigError, setting, validate

STALE_MARGIN = 0.1   # s beyond a link's delay and jitter before a neighbour counts as silent


@dataclass(frozen=True)
class LinkParams:
    """A link that delays and loses neighbour states: the link part of a scenario's [world]
    (firmware_sim.world.WorldParams) and of an agent's simulation-only [impairment]."""

    seed: int = setting(0, doc="seed of every random draw", lo=0)
    link_delay: float = setting(0.0, unit="s", lo=0.0, hi=5.0,
                                doc="mean one-way age of a neighbour's state when it arrives")
    link_jitter: float = setting(0.0, unit="s", lo=0.0, hi=5.0,
                                 doc="standard deviation of that age")
    link_loss: float = setting(0.0, lo=0.0, hi=0.95,
                               doc="long-run fraction of neighbour states lost")
    loss_burst: float = setting(1.0, unit="messages", lo=1.0,
                                doc="mean burst length of losses (1: independent losses; "
                                    "> 1: Gilbert-Elliott bursts)")

    def __post_init__(self) -> None:
        validate(self)
        if problem := loss_burst_problem(self.link_loss, self.loss_burst):
            raise ConfigError(f"{type(self).__name__}.loss_burst: {problem}")

    def staleness(self, at_least: float) -> float:
        """The staleness limit [s] for agents on this link: at least ``at_least`` [s], and
        longer than the link's delay (with four jitters and STALE_MARGIN), so that a robot
        that is alive is not taken for a silent one."""
        return max(at_least, self.link_delay + 4.0 * self.link_jitter + STALE_MARGIN)


@dataclass(frozen=True)
class ImpairmentSettings(LinkParams):
    """SIMULATION ONLY (written by ``boundswarm sitl``): the link of the scenario's [world]
    on the neighbour states this agent receives."""

    def describe(self) -> str:
        return (f"delay {self.link_delay:g} s, jitter {self.link_jitter:g} s, loss "
                f"{self.link_loss:g} in bursts of {self.loss_burst:g}, seed {self.seed}")


class ImpairedSwarm:
    """``inner`` (a SwarmPort) with the neighbour states of robot ``robot_id`` impaired by
    ``imp``; ``clock`` gives the time [s] on the clock of the inner port's ``received``
    stamps (UNIX time)."""

    def __init__(self, inner: SwarmPort, robot_id: int, imp: ImpairmentSettings,
                 clock: Callable[[], float]):
        self.inner, self.robot_id, self.imp, self.clock = inner, robot_id, imp, clock
        self._taken: dict[int, float] = {}     # sender -> stamp [s] of its newest state taken
        self._count: dict[int, int] = {}       # sender -> states taken (key of the draws)
        self._bad: dict[int, int] = {}         # sender -> its link's last loss_step
        # (due [s], n, sender, state, router's stamp [s] or None)
        self._pending: list[tuple[float, int, int, StateMsg, float | None]] = []
        self._pushed = 0
        self._held: dict[int, Received[StateMsg]] = {}
        self._view: Mapping[int, Received[StateMsg]] = MappingProxyType({})
        self.taken = self.lost = self.superseded = 0

    def publish(self, state: StateMsg) -> None:
        self.inner.publish(state)

    def obstacles(self) -> ObstaclesMsg | None:
        return self.inner.obstacles()

    def mission(self) -> MissionMsg | None:
        return self.inner.mission()

    def neighbours(self) -> Mapping[int, Received[StateMsg]]:
        """Per robot, the newest state (by stamp) that has come through the impaired link by
        now (a mapping never mutated after it is returned)."""
        imp = self.imp
        for sender, rec in self.inner.neighbours().items():
            if rec.msg.stamp <= self._taken.get(sender, -math.inf):
                continue                                   # nothing new from this robot
            self._taken[sender] = rec.msg.stamp
            k = self._count.get(sender, 0)
            self._count[sender] = k + 1
            self.taken += 1
            if imp.link_loss > 0.0:
                bad = loss_step(uniform(imp.seed, LINK_LOSS, self.robot_id, sender, k),
                                self._bad.get(sender, 0), imp.link_loss, imp.loss_burst)
                self._bad[sender] = bad
                if bad:
                    self.lost += 1
                    continue
            delay = imp.link_delay
            if imp.link_jitter > 0.0:
                delay += imp.link_jitter * normal(imp.seed, LINK_AGE, self.robot_id, sender, k)
            heapq.heappush(self._pending, (rec.received + max(delay, 0.0), self._pushed,
                                           sender, rec.msg, rec.routed))
            self._pushed += 1
        now, changed = self.clock(), False
        while self._pending and self._pending[0][0] <= now:
            due, _, sender, msg, routed = heapq.heappop(self._pending)
            held = self._held.get(sender)
            if held is not None and msg.stamp <= held.msg.stamp:
                self.superseded += 1                       # overtaken by a newer state
                continue
            self._held[sender] = Received(msg, due, routed)
            changed = True
        if changed:
            self._view = MappingProxyType(dict(self._held))
        return self._view

    def counters(self) -> dict:
        """States taken from the link, lost, overtaken by a newer one, and still in flight."""
        return {"taken": self.taken, "lost": self.lost, "superseded": self.superseded,
                "in_flight": len(self._pending)}
