"""The robot's own path over the last seconds: how far it has gone since a time.

The safety governor takes a neighbour's data of age t as that neighbour's share of the gap
between them when it last acted, and counts this robot's own path since that instant
(:func:`agent.governor.neighbour_radii`). The path is that of the pose the robot believes
(odometry, fused fixes): a jump of the estimate counts as travel.
"""
from __future__ import annotations

import math
from bisect import bisect_right


class Trail:
    """The believed positions of the last ``span`` [s]: their times [s] and the path [m]
    walked through them."""

    def __init__(self, span: float):
        self.span = span
        self._t: list[float] = []
        self._path: list[float] = []        # m, cumulative, from the first position
        self._x = self._y = math.nan

    def record(self, t: float, x: float, y: float) -> None:
        """The position (x, y) [m] at time t [s] (non-decreasing)."""
        step = 0.0 if math.isnan(self._x) else math.hypot(x - self._x, y - self._y)
        self._x, self._y = x, y
        self._t.append(t)
        self._path.append((self._path[-1] if self._path else 0.0) + step)
        if self._t[0] < t - 2.0 * self.span:      # drop the old half now and then
            cut = bisect_right(self._t, t - self.span) - 1
            del self._t[:cut], self._path[:cut]

    def since(self, t: float) -> float:
        """The path [m] from the last position recorded at or before t [s] (the first
        one, if none) to the newest (0 before any)."""
        return self.since_each(t, 0.0, 1)[0]

    def since_each(self, start: float, span: float, pieces: int) -> list[float]:
        """:meth:`since` at each of the instants start + span k / pieces [s], k = 0 ..
        pieces - 1 (one call for the splits of a neighbour's data age)."""
        t, path = self._t, self._path
        if not path:
            return [0.0] * pieces
        last = path[-1]
        return [last - path[max(bisect_right(t, start + span * k / pieces) - 1, 0)]
                for k in range(pieces)]
