"""Place exchange: two robots swap their places in the formation when both gain by it.

The formation's places are a set: robot i holds place ``slot`` (an index into the
mission's offsets, at first its own). Two robots that each stand nearer the other's
place swap them when the sum of their squared distances to their places falls by more
than ``gain_min`` [m^2] (CAPT's criterion, Turpin, Michael and Kumar 2014: pairwise, it
never brings the sum up, so exchanges cannot cycle). A robot far behind the formation no
longer crosses it to reach a place that a robot already there could take.

The handshake runs in the state messages every robot publishes (slot, partner, other),
over a link that delays and loses them, so each step is decided by one robot on what it
has heard (docs/controller.md, A18):

1. **Ask.** A robot i free for ``hold`` [s] asks the free neighbour j of higher id with the
   largest gain: it publishes partner = j, other = j's place.
2. **Give.** j, free, heard asked for its own place, checks the gain on its own data
   (above 0) and takes i's place at once: slot = i's place, partner = i, other = its old
   place.
3. **Take.** i, hearing j in its place (by j's newest state, in range or not), takes
   ``other``; so does a robot that gave up asking and then hears j name it from its
   place. j frees itself when it hears i in its old place, or no longer asking (then, if
   i stayed in its place, j takes its own back), or silent for ``hold``.
4. **Mend.** No handshake over a lossy link can make both sides sure of the other (the
   two generals' problem), so an exchange can be left half done: i gave up, then heard
   j's give late while j took its place back, and both hold j's old place. A free robot
   that hears a robot of lower id in its place leaves it for the nearest place that no
   robot it has heard of holds.

An asker gives up when j is busy with another robot or has not given within ``hold``; it
then waits ``hold`` before asking again, so that a late give mostly still finds it in its
place. ``hold`` is :data:`HOLD` staleness limits.

Plain floats and ints, and lists or arrays: agents run it interpreted on lists, the batch
simulator compiled on arrays (:mod:`firmware_sim.compiled`), within one robot's period
(:mod:`agent.period`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from agent.formation import place

if TYPE_CHECKING:
    from agent.avoidance import FloatSeq, IntSeq
    from agent.formation import Places
    from agent.neighbours import Reports

NOBODY = -1     # no partner, no place
HOLD = 2.0      # the handshake's hold [s], in staleness limits (module docstring)


class Exchange(NamedTuple):
    """One robot's part in the exchanges: its place and the handshake in progress."""

    slot: int               # its place: an index into the formation's offsets
    partner: int = NOBODY   # the robot it asks or gives to
    other: int = NOBODY     # the place that goes the other way (asked for, or given)
    giving: bool = False    # it gave its place and waits for the partner to take it
    since: float = -math.inf    # s, when it last asked, took, gave or gave up


class Heard(NamedTuple):
    """What a robot has heard, for its exchange step: every robot's newest report, and
    which of them are fresh neighbours in range, where those are now."""

    reports: Reports        # every robot's newest report (its own row is passed over)
    rows: IntSeq            # the fresh neighbours in range: their rows of ``reports``
    x: FloatSeq             # m, where each of those is now
    y: FloatSeq             # m
    n: int                  # how many there are
    partner: int            # the row of its partner's newest report (-1: none heard)
    partner_age: float      # s, that report's age (inf: none)


def exchange_gain(x_i: float, y_i: float, gx_i: float, gy_i: float, x_j: float, y_j: float,
                  gx_j: float, gy_j: float) -> float:
    """How much [m^2] the sum of the squared distances of robots i and j (at x, y [m]) to
    their places (gx, gy [m]) falls if they swap them: 2 (p_j - p_i) . (g_i - g_j)."""
    return 2.0 * ((x_j - x_i) * (gx_i - gx_j) + (y_j - y_i) * (gy_i - gy_j))


def free_place(me: int, x: float, y: float, t: float, slot: int, reports: Reports,
               places: Places) -> int:
    """The place nearest to (x, y) [m] at time t [s] that no robot holds, as far as robot
    ``me`` knows: the slot every other robot last published (any age; NOBODY: none), and
    its own ``slot`` counted as held. NOBODY when every place is held."""
    held = np.zeros(len(places.offsets), np.bool_)
    held[slot] = True
    for r in range(len(reports.robot)):
        if (reports.robot[r] != me and reports.stamp[r] > -math.inf
                and reports.slot[r] >= 0):
            held[reports.slot[r]] = True
    best, pick = math.inf, NOBODY
    for s in range(len(places.offsets)):
        if not held[s]:
            px, py = place(places, s, t)
            d = (px - x) * (px - x) + (py - y) * (py - y)
            if d < best:
                best, pick = d, s
    return pick


def exchange_step(me: int, x: float, y: float, t: float, ex: Exchange, heard: Heard,
                  places: Places, gain_min: float, staleness: float) -> Exchange:
    """Robot ``me`` (at x, y [m], believed) one period on, at time t [s]: its exchange
    state after hearing ``heard`` (the slot, partner and other its fresh neighbours in
    range last published, NOBODY where they published none; its partner's newest report,
    whatever its range; what every robot last published, :func:`free_place`). ``places``
    (agent.formation.place); ``staleness`` [s] the neighbour data's staleness limit."""
    hold = HOLD * staleness
    rep = heard.reports
    pal_slot, pal_partner = NOBODY, NOBODY
    if heard.partner >= 0:
        pal_slot, pal_partner = rep.slot[heard.partner], rep.partner[heard.partner]
    pal_age = heard.partner_age
    if ex.giving:
        if pal_slot == ex.other:                                 # taken
            return Exchange(ex.slot, NOBODY, NOBODY, False, t)
        if pal_age <= hold and pal_partner != me:                # heard no longer asking:
            if pal_slot == ex.slot:                              # it stayed, so take back
                return Exchange(ex.other, NOBODY, NOBODY, False, t)   # the place given
            return Exchange(ex.slot, NOBODY, NOBODY, False, t)
        if pal_age > hold and t - ex.since > hold:               # the asker fell silent
            return Exchange(ex.slot, NOBODY, NOBODY, False, t)
        return ex
    if ex.partner != NOBODY and pal_slot == ex.slot:      # the robot asked gave its place
        return Exchange(ex.other, NOBODY, NOBODY, False, t)
    for q in range(heard.n):  # one that names this robot from its place: it gave, late
        r = heard.rows[q]
        if rep.slot[r] == ex.slot and rep.partner[r] == me and rep.other[r] != NOBODY:
            return Exchange(rep.other[r], NOBODY, NOBODY, False, t)
    if ex.partner != NOBODY:
        busy = pal_partner != NOBODY and pal_partner != me
        if busy or t - ex.since > hold:
            return Exchange(ex.slot, NOBODY, NOBODY, False, t)   # give up, then wait
        return ex
    # a place two robots hold (an exchange left half done): the one of higher id leaves
    # it for the nearest free one
    for q in range(heard.n):
        r = heard.rows[q]
        if rep.slot[r] == ex.slot and rep.robot[r] < me:
            free = free_place(me, x, y, t, ex.slot, rep, places)
            if free != NOBODY:
                return Exchange(free, NOBODY, NOBODY, False, t)
    if t - ex.since < hold or gain_min <= 0.0:
        return ex
    # asked for this robot's place: give it to the asker that gains most; else ask the
    # free neighbour of higher id that gains most
    q = _best(me, x, y, t, ex.slot, True, heard, places, 0.0)
    if q >= 0:
        r = heard.rows[q]
        return Exchange(rep.slot[r], rep.robot[r], ex.slot, True, t)
    q = _best(me, x, y, t, ex.slot, False, heard, places, gain_min)
    if q >= 0:
        r = heard.rows[q]
        return Exchange(ex.slot, rep.robot[r], rep.slot[r], False, t)
    return ex


def _best(me: int, x: float, y: float, t: float, slot: int, asked: bool, heard: Heard,
          places: Places, least: float) -> int:
    """The neighbour (its index in ``heard``; -1: none) with the largest gain above
    ``least`` [m^2] of those that ask robot ``me`` for its place ``slot`` (``asked``), or
    else of the free ones of higher id."""
    rep = heard.reports
    gx, gy = place(places, slot, t)
    best, pick = least, -1
    for q in range(heard.n):
        r = heard.rows[q]
        if asked:
            candidate = rep.partner[r] == me and rep.other[r] == slot
        else:
            candidate = rep.robot[r] > me and rep.partner[r] == NOBODY
        if candidate and rep.slot[r] != NOBODY and rep.slot[r] != slot:
            ox, oy = place(places, rep.slot[r], t)
            gain = exchange_gain(x, y, gx, gy, heard.x[q], heard.y[q], ox, oy)
            if gain > best:
                best, pick = gain, q
    return pick
