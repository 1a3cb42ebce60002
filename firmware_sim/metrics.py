"""Ground-truth metrics of a run: safety (distances, collisions) and convergence.

Fed as the run goes (no full trajectory needed, so it serves 10 000-robot batch runs and
SITL alike): :meth:`RunMetrics.observe_geometry` at every physics (sub)step,
:meth:`RunMetrics.observe_period` at every control period (from
:func:`firmware_sim.swarm_step.period_summary`, which applies the tolerance below).
:meth:`RunMetrics.summary` gives the ``metrics.json`` dictionary (its keys are listed in
docs/formats.md).

Convergence tolerance per robot: |p_d_dot| / K + 0.25 m, and the deadlock rule, as the
agents' detector has them (:mod:`agent.progress`). The law's only feed-forward is the
heading rate in TRACK; v has none of the reference velocity, so in steady state a robot
trails its reference by |p_d_dot| / K (docs/controller.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agent.progress import WINDOW, stuck


@dataclass
class RunMetrics:
    """Accumulates the metrics of one run of robots ``ids`` with collision distance ``a``."""

    ids: np.ndarray
    a: float
    min_pair_distance: float = math.inf
    min_obstacle_clearance: float = math.inf
    min_pair_time: float | None = None               # s
    min_clearance_time: float | None = None          # s
    worst_pair: tuple[int, int] | None = None        # robot ids
    worst_clearance: tuple[int, int] | None = None   # robot id, obstacle index
    killed: list = field(default_factory=list)       # robot ids whose agent died
    max_pose_error: float = 0.0                      # m, believed position vs truth
    pose_holds: list = field(default_factory=list)   # robot ids held: no pose fix
    max_abs_v: float = 0.0
    max_abs_u: float = 0.0
    mode_switches: int = 0
    colliding_pairs: set = field(default_factory=set)
    robots_in_obstacles: set = field(default_factory=set)
    geometry_t: list = field(default_factory=list)
    geometry_dmin: list = field(default_factory=list)
    geometry_clear: list = field(default_factory=list)
    _last_bad_t: float | None = None
    _seen_t: list = field(default_factory=list)
    _final_err: np.ndarray | None = None
    _final_within: np.ndarray | None = None
    _errors: list = field(default_factory=list)      # (t, tracking errors, within) once a second
    _governed: np.ndarray | None = None              # per robot: periods the governor acted
    _periods: np.ndarray | None = None               # per robot: periods it ran (alive)
    governor_min_allowed: float = math.inf           # m/s
    place_changes: int = 0                           # a robot took another place
                                                     # (agent.exchange; two an exchange)
    shared_places: list = field(default_factory=list)    # robot ids: a live robot's place
                                                         # that another live one holds too

    def observe_geometry(self, t: float, pos: np.ndarray, pairs: np.ndarray,
                         robots: np.ndarray, clearance: np.ndarray,
                         index: np.ndarray | None = None) -> None:
        """Robot positions (N, 2) at time t [s]; ``pairs`` (P, 2) of robots to check (every
        pair that could be the closest or closer than a); ``clearance`` (R, K) [m] from
        robots ``robots`` (R,) to obstacle surfaces, inf where there is none. ``index``
        maps the rows of ``pos`` to the swarm's robots when ``pos`` holds only some."""
        ids = self.ids if index is None else self.ids[index]
        rows = np.arange(len(pos)) if index is None else np.asarray(index)
        d = np.hypot(*(pos[pairs[:, 0]] - pos[pairs[:, 1]]).T)
        dmin = float(d.min()) if len(d) else math.inf
        cmin = float(clearance.min()) if clearance.size else math.inf
        close = pairs[d < self.a]
        inside = robots[(clearance < 0.0).any(axis=1)] if clearance.size else robots[:0]
        who = np.full(4, -1)
        if len(d):
            who[:2] = rows[pairs[int(d.argmin())]]
        if clearance.size:
            r, k = np.unravel_index(int(clearance.argmin()), clearance.shape)
            who[2:] = rows[robots[r]], k
        self.observe_extremes(t, dmin, cmin, [(int(ids[i]), int(ids[j])) for i, j in close],
                              [int(ids[i]) for i in inside], who)

    def observe_extremes(self, t: float, dmin: float, cmin: float,
                         colliding_pairs: list[tuple[int, int]],
                         robots_in_obstacles: list[int],
                         who: np.ndarray | None = None) -> None:
        """The closest pair's distance [m] and the smallest clearance [m] at time t [s]
        (inf: none in range), with the robot-id pairs closer than a and the robots inside
        an obstacle; ``who`` = (robot index, robot index, robot index, obstacle index) of
        that pair and that clearance (indices into ``ids``; -1: none), when known."""
        if dmin < self.min_pair_distance:
            self.min_pair_distance, self.min_pair_time = dmin, t
            if who is not None:
                i, j = sorted((int(self.ids[who[0]]), int(self.ids[who[1]])))
                self.worst_pair = (i, j)
        if cmin < self.min_obstacle_clearance:
            self.min_obstacle_clearance, self.min_clearance_time = cmin, t
            if who is not None:
                self.worst_clearance = (int(self.ids[who[2]]), int(who[3]))
        self.colliding_pairs.update(colliding_pairs)
        self.robots_in_obstacles.update(robots_in_obstacles)
        self.geometry_t.append(t)
        self.geometry_dmin.append(dmin)
        self.geometry_clear.append(cmin)

    def observe_period(self, t: float, max_abs_v: float, max_abs_u: float, switches: int,
                       error: np.ndarray, within: np.ndarray, all_within: bool) -> None:
        """A period's summary at t [s]: largest |v| [m/s] and |u| [rad/s], mode switches
        since the last period, each robot's tracking error [m] and whether it is within
        its tolerance. ``error`` and ``within`` are kept as the final ones (not copied)."""
        self.max_abs_v = max(self.max_abs_v, max_abs_v)
        self.max_abs_u = max(self.max_abs_u, max_abs_u)
        self.mode_switches += switches
        if not all_within or self.shared_places:     # two robots in one place: not yet
            self._last_bad_t = t
        self._seen_t.append(t)
        self._final_err, self._final_within = error, within
        if not self._errors or t >= self._errors[-1][0] + 1.0:
            self._errors.append((t, error.copy(), within.copy()))
            while self._errors[0][0] < t - WINDOW - 1.0:
                self._errors.pop(0)

    def observe_places(self, slots: np.ndarray, before: np.ndarray, alive: np.ndarray
                       ) -> None:
        """A period's places (:mod:`agent.exchange`): each robot's slot now and the period
        before. Until the next, :meth:`observe_period` counts a formation whose live robots
        share a place as not within tolerance."""
        changed = int(np.count_nonzero(slots != before))
        self.place_changes += changed
        if changed == 0 and not self.shared_places:
            return      # none changed: none shared now (a death only ends a sharing)
        live = slots[alive]
        _, first, count = np.unique(live, return_index=True, return_counts=True)
        shared = np.isin(live, live[first[count > 1]])
        self.shared_places = [int(r) for r in self.ids[alive][shared]]

    def observe_governor(self, limit: np.ndarray, alive: np.ndarray) -> None:
        """A period's governor limits [m/s] per robot (inf where it left the command alone)
        and which robots ran the law."""
        if self._governed is None:
            self._governed = np.zeros(len(self.ids), np.int64)
            self._periods = np.zeros(len(self.ids), np.int64)
        acted = np.isfinite(limit) & alive
        self._governed += acted
        self._periods += alive
        if acted.any():
            self.governor_min_allowed = min(self.governor_min_allowed,
                                            float(limit[acted].min()))

    def _governor_summary(self) -> dict:
        gov, per = self._governed, self._periods
        if gov is None or per is None:
            return {"governor_share": 0.0, "governor_share_by_robot": {},
                    "governor_min_allowed": None}
        return {"governor_share": _share(gov.sum(), per.sum()),
                "governor_share_by_robot": {int(r): _share(g, p)
                                            for r, g, p in zip(self.ids, gov, per)},
                "governor_min_allowed": _finite_or_none(self.governor_min_allowed)}

    @property
    def deadlocked(self) -> list[int]:
        """The robots (ids) outside their tolerance at the end and WINDOW seconds before
        it that shed less than PROGRESS of tracking error since: stuck, or trailing their
        place at its own speed (agent.progress)."""
        if self._final_within is None or not self._errors:
            return []
        t_end = self._errors[-1][0]
        then = [(e, w) for t, e, w in self._errors if t <= t_end - WINDOW]
        if not then:
            return []
        error, within = then[-1]
        held = stuck(self._errors[-1][1], error, ~self._final_within, ~within)
        return [int(i) for i in self.ids[held]]

    @property
    def convergence_time(self) -> float | None:
        """Earliest observed t [s] after which every robot stays within tolerance."""
        if self._final_within is None or not self._final_within.all():
            return None
        if self._last_bad_t is None:
            return self._seen_t[0]
        later = [t for t in self._seen_t if t > self._last_bad_t]
        return later[0] if later else None

    def summary(self, scenario: str, duration: float) -> dict:
        conv = self.convergence_time
        stuck = [] if self._final_within is None else \
            [int(i) for i in self.ids[~self._final_within]]
        return {
            "scenario": scenario,
            "robots": int(len(self.ids)),
            "duration": float(duration),
            "min_pair_distance": _finite_or_none(self.min_pair_distance),
            "min_pair_time": self.min_pair_time,
            "worst_pair": list(self.worst_pair) if self.worst_pair else None,
            "min_obstacle_clearance": _finite_or_none(self.min_obstacle_clearance),
            "min_clearance_time": self.min_clearance_time,
            "worst_clearance_robot": self.worst_clearance[0] if self.worst_clearance else None,
            "worst_clearance_obstacle": (self.worst_clearance[1] if self.worst_clearance
                                         else None),
            "max_abs_v": self.max_abs_v,
            "max_abs_u": self.max_abs_u,
            "converged": conv is not None,
            "convergence_time": conv,
            "final_max_tracking_error": (None if self._final_err is None
                                         else float(self._final_err.max(initial=0.0))),
            "collisions": len(self.colliding_pairs) + len(self.robots_in_obstacles),
            "colliding_pairs": sorted(self.colliding_pairs),
            "robots_in_obstacles": sorted(self.robots_in_obstacles),
            "stuck_robots": stuck,
            "deadlocked": bool(self.deadlocked),
            "deadlocked_robots": self.deadlocked,
            "killed_robots": list(self.killed),
            "mode_switches": self.mode_switches,
            "max_pose_error": self.max_pose_error,
            "pose_failsafe_robots": list(self.pose_holds),
            "place_changes": self.place_changes,
            "shared_places": list(self.shared_places),
            **self._governor_summary(),
        }


def _share(count: np.ndarray | int, periods: np.ndarray | int) -> float:
    return float(count / periods) if periods else 0.0


def _finite_or_none(x: float) -> float | None:
    """JSON has no infinity: a distance never observed (no pair in range) is null."""
    return float(x) if math.isfinite(x) else None
