"""The robot's own motion over the last seconds: how far it has gone, and where, since a time.

The safety governor takes a neighbour's data of age t as that neighbour's share of the gap
between them when it last acted, and counts this robot's own motion since that instant
(:func:`agent.discs.neighbour_radii`). The motion is that of the pose the robot believes
(odometry, fused fixes): a jump of the estimate counts as travel.

The positions are an :class:`OwnPath`: a ring of (time, x, y, path walked) records, the
oldest first. An agent keeps its own in a :class:`Trail` (lists, a record every tick); the
batch simulator keeps one ring per robot, a record every period. The period reads either
through the same functions (:func:`path_since`, :func:`own_motion`), in plain floats:
agents run them interpreted, the batch simulator compiled.
"""
from __future__ import annotations

import math
from bisect import bisect_right
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    from agent.avoidance import FloatBuf, FloatSeq, IntBuf

SPLITS = 4           # pieces of a neighbour's data age paired with this robot's path
TIME_TOL = 1e-9      # s, a record this near a piece's boundary counts as at it


class OwnPath(NamedTuple):
    """The robot's believed positions over its last seconds: a ring of ``size`` records of
    which ``n`` are kept, the oldest at index ``first``, times non-decreasing."""

    t: FloatSeq         # s, when each position was believed (the clock of the stamps)
    x: FloatSeq         # m
    y: FloatSeq         # m
    walked: FloatBuf    # m, the path walked through the records, cumulative
    first: int
    n: int
    size: int


class Splits(NamedTuple):
    """This robot's motion over each split k of a neighbour's data age (k = 0 the
    stamp's), toward the newest position: the rows :func:`own_motion` fills, then those
    :func:`trail_motion` derives from them. Each row holds one float per split."""

    walked: FloatBuf        # m, path since the last record at or before the split's start
    walked_end: FloatBuf    # m, path since the first record at or after its end
    start_x: FloatBuf       # m, displacement east since that start record
    start_y: FloatBuf       # m, north
    end_x: FloatBuf         # m, displacement east since that end record
    end_y: FloatBuf         # m, north
    start_len: FloatBuf     # m, the length of (start_x, start_y)
    end_len: FloatBuf       # m, the length of (end_x, end_y)
    bulge: FloatBuf         # m, half the minor axis of the ellipse of where it was within k
    dominated: FloatBuf     # 1.0 where split k + 1 dominates split k, else 0.0


def trail_motion(s: Splits) -> None:
    """Fill the derived rows of ``s`` from its first six, once for all the neighbours that
    share it: for each split k, the lengths [m] of this robot's displacement since the
    split's start and since its end; half the minor axis [m] of the ellipse of the
    positions it can have had within the split (foci where it was at the split's start and
    end, the path walked within it); and 1.0 where the next split dominates split k (it
    stood still within k, or moved over k as over k + 1: the same positions at and after
    their starts and ends, as where both fall between two recorded positions, data younger
    than the robot's period; the next split ends later), else 0.0 (the last split: 0.0)."""
    splits = len(s.walked)
    for k in range(splits):
        path, start_x, start_y = s.walked[k], s.start_x[k], s.start_y[k]
        end_x, end_y = s.end_x[k], s.end_y[k]
        within = path - s.walked_end[k]        # m, walked within the split
        chord_x, chord_y = start_x - end_x, start_y - end_y
        s.start_len[k] = math.sqrt(start_x * start_x + start_y * start_y)
        s.end_len[k] = math.sqrt(end_x * end_x + end_y * end_y)
        s.bulge[k] = 0.5 * math.sqrt(max(within * within - chord_x * chord_x
                                         - chord_y * chord_y, 0.0))
        if k + 1 == splits:
            s.dominated[k] = 0.0
            continue
        same = (path == s.walked[k + 1] and s.walked_end[k] == s.walked_end[k + 1]
                and start_x == s.start_x[k + 1] and start_y == s.start_y[k + 1]
                and end_x == s.end_x[k + 1] and end_y == s.end_y[k + 1])
        # moved over k as over k + 1, or stood still within k
        s.dominated[k] = 1.0 if path == s.walked_end[k] or same else 0.0


def at_or_before(path: OwnPath, when: float) -> int:
    """The last record (0: the oldest) at or before time ``when`` [s]; the oldest if none
    is. The records are nearly evenly spaced (a robot's ticks), so the search starts where
    the time would lie and walks from there. ``path`` holds a record at least."""
    t, first, size, last = path.t, path.first, path.size, path.n - 1
    newest, oldest = t[(first + last) % size], t[first]
    if when + TIME_TOL >= newest:
        return last
    if when + TIME_TOL < oldest:
        return 0
    i = int((when - oldest) / (newest - oldest) * last)
    i = 0 if i < 0 else (last if i > last else i)
    while i < last and t[(first + i + 1) % size] <= when + TIME_TOL:
        i += 1
    while i > 0 and t[(first + i) % size] > when + TIME_TOL:
        i -= 1
    return i


def path_since(path: OwnPath, start: float) -> tuple[float, float, float]:
    """(walked, lo, hi): the path [m] to the newest position from the last one recorded at
    or before ``start`` [s] (the oldest, if none; 0 before any), :func:`own_motion`'s first
    value; and the same for every time whose TIME_TOL later lies in [lo, hi) [s]: the
    record's time and the next one's (-inf, inf at the ends), for a caller that asks
    again."""
    n = path.n
    if n == 0:
        return 0.0, -math.inf, math.inf
    t, first, size = path.t, path.first, path.size
    i = at_or_before(path, start)
    j = (first + i) % size
    lo = t[j] if i > 0 or t[j] <= start + TIME_TOL else -math.inf
    hi = t[(first + i + 1) % size] if i < n - 1 else math.inf
    return path.walked[(first + n - 1) % size] - path.walked[j], lo, hi


def own_motion(path: OwnPath, start: float, span: float, key: IntBuf, out: Splits) -> None:
    """This robot's motion over each split k of the ``span`` [s] from ``start`` [s] (the
    neighbour's stamp and data age, split evenly into len(out.walked) pieces), into
    ``out`` (:class:`Splits`, all zero before any record): from the last record at or
    before the split's start (the oldest, if none) and from the first at or after its end
    (the newest, if none) to the newest. ``key`` (two ints a split) holds the records the
    last call used: where this call's are the same, ``out`` holds its motion already and is
    left as it is (neighbours whose pieces fall between the same records share it). Set
    ``key[0]`` to -1 to compute afresh."""
    pieces = len(out.walked)
    if path.n == 0:
        for k in range(pieces):
            out.walked[k] = out.walked_end[k] = out.start_x[k] = out.start_y[k] = 0.0
            out.end_x[k] = out.end_y[k] = 0.0
        trail_motion(out)
        key[0] = -1
        return
    t, first, size, last = path.t, path.first, path.size, path.n - 1
    same = key[0] >= 0
    # one search, then forward: the boundaries come in order
    i = at_or_before(path, start)
    for k in range(pieces):
        if k > 0:
            lo = start + span * k / pieces
            while i < last and t[(first + i + 1) % size] <= lo + TIME_TOL:
                i += 1
        hi = start + span * (k + 1) / pieces - TIME_TOL
        j = i
        while j > 0 and t[(first + j - 1) % size] >= hi:
            j -= 1
        while j < last and t[(first + j) % size] < hi:
            j += 1
        if key[2 * k] != i or key[2 * k + 1] != j:
            same = False
            key[2 * k], key[2 * k + 1] = i, j
    if same:
        return
    newest = (first + last) % size
    walked, x, y = path.walked[newest], path.x[newest], path.y[newest]
    for k in range(pieces):
        i, j = (first + key[2 * k]) % size, (first + key[2 * k + 1]) % size
        out.walked[k], out.walked_end[k] = walked - path.walked[i], walked - path.walked[j]
        out.start_x[k], out.start_y[k] = x - path.x[i], y - path.y[i]
        out.end_x[k], out.end_y[k] = x - path.x[j], y - path.y[j]
    trail_motion(out)


def splits_of(rows: tuple[list[float], ...]) -> Splits:
    """The splits whose first six rows are ``rows`` (as :func:`own_motion` fills them),
    with the rows derived from them (:func:`trail_motion`)."""
    pieces = len(rows[0])
    s = Splits(*(list(r) for r in rows), *([0.0] * pieces for _ in range(4)))
    trail_motion(s)
    return s


def straight(speed: float, ux: float, uy: float, age: float, pieces: int) -> Splits:
    """The splits of a robot that drove straight along the unit vector (``ux``, ``uy``)
    at ``speed`` [m/s] over the whole ``age`` [s], split ``pieces`` ways: for a statement
    or a benchmark of the governor's discs."""
    paths = [speed * age * (pieces - k) / pieces for k in range(pieces)]
    inner = [speed * age * (pieces - k - 1) / pieces for k in range(pieces)]
    return splits_of((paths, inner, [d * ux for d in paths], [d * uy for d in paths],
                      [d * ux for d in inner], [d * uy for d in inner]))


class Trail:
    """An agent's own believed positions of the last ``span`` [s] (at least): the
    :class:`OwnPath` its period reads (:meth:`path`), a record each tick."""

    def __init__(self, span: float):
        self.span = span
        self._t: list[float] = []
        self._walked: list[float] = []        # m, cumulative, from the first position
        self._x: list[float] = []
        self._y: list[float] = []

    def record(self, t: float, x: float, y: float) -> None:
        """The position (x, y) [m] at time t [s] (non-decreasing)."""
        step = math.hypot(x - self._x[-1], y - self._y[-1]) if self._x else 0.0
        self._t.append(t)
        self._walked.append((self._walked[-1] if self._walked else 0.0) + step)
        self._x.append(x)
        self._y.append(y)
        if self._t[0] < t - 2.0 * self.span:      # drop the old half now and then
            cut = bisect_right(self._t, t - self.span) - 1
            del self._t[:cut], self._walked[:cut], self._x[:cut], self._y[:cut]

    def path(self) -> OwnPath:
        """The records, for the period (read, do not change)."""
        n = len(self._t)
        return OwnPath(self._t, self._x, self._y, self._walked, 0, n, max(n, 1))

