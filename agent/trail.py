"""The robot's own motion over the last seconds: how far it has gone, and where, since a time.

The safety governor takes a neighbour's data of age t as that neighbour's share of the gap
between them when it last acted, and counts this robot's own motion since that instant
(:func:`agent.governor.neighbour_radii`). The motion is that of the pose the robot believes
(odometry, fused fixes): a jump of the estimate counts as travel.
"""
from __future__ import annotations

import math
from bisect import bisect_right

from agent.governor import TRAIL_ROWS, trail_motion

Splits = tuple[list[float], ...]


def with_motion(rows: tuple[list[float], ...]) -> Splits:
    """The six rows of a trail (:meth:`Trail.splits`) completed with the rows the governor
    derives from them (agent.governor.trail_motion)."""
    pieces = len(rows[0])
    trail = tuple(rows) + tuple([0.0] * pieces for _ in range(TRAIL_ROWS - len(rows)))
    trail_motion(trail)
    return trail


def straight(speed: float, ux: float, uy: float, age: float, pieces: int) -> Splits:
    """The splits (as :meth:`Trail.splits` gives them) of a robot that drove straight along
    the unit vector (``ux``, ``uy``) at ``speed`` [m/s] over the whole ``age`` [s], split
    ``pieces`` ways: for a statement or a benchmark of the governor's discs."""
    paths = [speed * age * (pieces - k) / pieces for k in range(pieces)]
    inner = [speed * age * (pieces - k - 1) / pieces for k in range(pieces)]
    return with_motion((paths, inner, [d * ux for d in paths], [d * uy for d in paths],
                        [d * ux for d in inner], [d * uy for d in inner]))


class Trail:
    """The believed positions of the last ``span`` [s]: their times [s], the positions [m]
    and the path [m] walked through them."""

    def __init__(self, span: float):
        self.span = span
        self._t: list[float] = []
        self._path: list[float] = []        # m, cumulative, from the first position
        self._x: list[float] = []
        self._y: list[float] = []
        # the splits given since the last record, by where their pieces' boundaries fall
        # among the recorded times: neighbours whose pieces start and end between the same
        # records (the same stamp, or stamps within a period of the trail) share them
        self._given: dict[tuple[int, ...], Splits] = {}

    def record(self, t: float, x: float, y: float) -> None:
        """The position (x, y) [m] at time t [s] (non-decreasing)."""
        step = math.hypot(x - self._x[-1], y - self._y[-1]) if self._x else 0.0
        self._t.append(t)
        self._path.append((self._path[-1] if self._path else 0.0) + step)
        self._x.append(x)
        self._y.append(y)
        self._given = {}
        if self._t[0] < t - 2.0 * self.span:      # drop the old half now and then
            cut = bisect_right(self._t, t - self.span) - 1
            del self._t[:cut], self._path[:cut], self._x[:cut], self._y[:cut]

    def path_since(self, start: float) -> float:
        """The path [m] to the newest position from the last position recorded at or
        before ``start`` [s] (the first, if none): :meth:`splits`'s first value, alone."""
        t, path = self._t, self._path
        if not path:
            return 0.0
        return path[-1] - path[max(bisect_right(t, start) - 1, 0)]

    def splits(self, start: float, span: float, pieces: int) -> Splits:
        """This robot's motion over each piece k = 0 .. ``pieces`` - 1 of the time from
        ``start`` [s], ``span`` [s] long, split evenly, as
        :func:`agent.governor.neighbour_radii` takes it: the path [m] to the newest
        position from the last position recorded at or before the piece's start, and from
        the first at or after its end (the newest, if none); the displacement east and
        north [m] to the newest position from each of those two. All zero before any.
        Then the rows the governor derives from those (agent.governor.trail_motion). The
        lists are shared with every caller whose pieces fall between the same recorded
        positions until the next record: read, do not change."""
        t, path, xs, ys = self._t, self._path, self._x, self._y
        if not path:
            return with_motion(tuple([0.0] * pieces for _ in range(6)))
        # where each boundary falls among the recorded times: the index past the last
        # time at or before it, negated where a time equals it
        key = []
        for m in range(pieces + 1):
            edge = start + span * m / pieces
            i = bisect_right(t, edge)
            key.append(-i if i and t[i - 1] == edge else i)
        answer = self._given.get(tuple(key))
        if answer is not None:
            return answer
        # each boundary's last position at or before it, and first at or after it
        last, newest, x, y = path[-1], len(path) - 1, xs[-1], ys[-1]
        first = [max(abs(i) - 1, 0) for i in key[:-1]]
        end = [-i - 1 if i < 0 else min(i, newest) for i in key[1:]]
        answer = with_motion(([last - path[i] for i in first], [last - path[j] for j in end],
                              [x - xs[i] for i in first], [y - ys[i] for i in first],
                              [x - xs[j] for j in end], [y - ys[j] for j in end]))
        self._given[tuple(key)] = answer
        return answer
