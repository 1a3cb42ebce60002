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
simulator compiled on arrays (:mod:`firmware_sim.compiled`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from agent.formation import reference_point

if TYPE_CHECKING:
    from collections.abc import Sequence
    from typing import TypeAlias

    import numpy.typing as npt

    from agent.avoidance import FloatSeq

    # Ints: a list in an agent, an array compiled.
    IntSeq: TypeAlias = Sequence[int] | npt.NDArray[np.int64]

NOBODY = -1     # no partner, no place
HOLD = 2.0      # the handshake's hold [s], in staleness limits (module docstring)


class Exchange(NamedTuple):
    """One robot's part in the exchanges: its place and the handshake in progress."""

    slot: int               # its place: an index into the formation's offsets
    partner: int = NOBODY   # the robot it asks or gives to
    other: int = NOBODY     # the place that goes the other way (asked for, or given)
    giving: bool = False    # it gave its place and waits for the partner to take it
    since: float = -math.inf    # s, when it last asked, took, gave or gave up


def place(offsets: np.ndarray, motion: np.ndarray, slot: int, t: float
          ) -> tuple[float, float]:
    """Where place ``slot`` is at time t [s]: x, y [m] (``motion``: centre0 x, y [m],
    velocity x, y [m/s], omega [rad/s])."""
    x, y, _, _ = reference_point(offsets[slot, 0], offsets[slot, 1], motion[0], motion[1],
                                 motion[2], motion[3], motion[4], t)
    return x, y


def exchange_gain(x_i: float, y_i: float, gx_i: float, gy_i: float, x_j: float, y_j: float,
                  gx_j: float, gy_j: float) -> float:
    """How much [m^2] the sum of the squared distances of robots i and j (at x, y [m]) to
    their places (gx, gy [m]) falls if they swap them: 2 (p_j - p_i) . (g_i - g_j)."""
    return 2.0 * ((x_j - x_i) * (gx_i - gx_j) + (y_j - y_i) * (gy_i - gy_j))


def free_place(x: float, y: float, t: float, slot: int, known_slot: FloatSeq,
               offsets: np.ndarray, motion: np.ndarray) -> int:
    """The place nearest to (x, y) [m] at time t [s] that no robot holds, as far as this
    robot knows: ``known_slot`` the slot every robot last published (any age; NOBODY:
    none), ``slot`` counted as held. NOBODY when every place is held."""
    held = np.zeros(len(offsets), np.bool_)
    held[slot] = True
    for r in range(len(known_slot)):
        if known_slot[r] >= 0:
            held[int(known_slot[r])] = True
    best, pick = math.inf, NOBODY
    for s in range(len(offsets)):
        if not held[s]:
            px, py = place(offsets, motion, s, t)
            d = (px - x) * (px - x) + (py - y) * (py - y)
            if d < best:
                best, pick = d, s
    return pick


def exchange_step(me: int, x: float, y: float, t: float, ex: Exchange, nbr_id: IntSeq,
                  nbr_x: FloatSeq, nbr_y: FloatSeq, nbr_slot: IntSeq, nbr_partner: IntSeq,
                  nbr_other: IntSeq, pal_slot: int, pal_partner: int, pal_age: float,
                  known_slot: FloatSeq, offsets: np.ndarray, motion: np.ndarray,
                  gain_min: float, staleness: float) -> Exchange:
    """Robot ``me`` (at x, y [m], believed) one period on, at time t [s]: its exchange
    state after hearing its fresh neighbours in range (ids, positions [m], and the slot,
    partner and other they last published; NOBODY where they published none), its partner
    (the slot and partner it last published, and that state's age [s]; NOBODY and inf
    when it has none or never heard it), whatever its range, and what every robot last
    published (:func:`free_place`). ``offsets`` (S, 2) [m] and ``motion`` give the places
    (:func:`place`); ``staleness`` [s] the neighbour data's staleness limit."""
    m = len(nbr_id)
    hold = HOLD * staleness
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
    for q in range(m):       # one that names this robot from its place: it gave, late
        if nbr_slot[q] == ex.slot and nbr_partner[q] == me and nbr_other[q] != NOBODY:
            return Exchange(nbr_other[q], NOBODY, NOBODY, False, t)
    if ex.partner != NOBODY:
        busy = pal_partner != NOBODY and pal_partner != me
        if busy or t - ex.since > hold:
            return Exchange(ex.slot, NOBODY, NOBODY, False, t)   # give up, then wait
        return ex
    # a place two robots hold (an exchange left half done): the one of higher id leaves
    # it for the nearest free one
    for q in range(m):
        if nbr_slot[q] == ex.slot and nbr_id[q] < me:
            free = free_place(x, y, t, ex.slot, known_slot, offsets, motion)
            if free != NOBODY:
                return Exchange(free, NOBODY, NOBODY, False, t)
    if t - ex.since < hold or gain_min <= 0.0:
        return ex
    # asked for this robot's place: give it to the asker that gains most; else ask the
    # free neighbour of higher id that gains most
    q = _best(me, x, y, t, ex.slot, True, nbr_id, nbr_x, nbr_y, nbr_slot, nbr_partner,
              nbr_other, offsets, motion, 0.0)
    if q >= 0:
        return Exchange(nbr_slot[q], nbr_id[q], ex.slot, True, t)
    q = _best(me, x, y, t, ex.slot, False, nbr_id, nbr_x, nbr_y, nbr_slot, nbr_partner,
              nbr_other, offsets, motion, gain_min)
    if q >= 0:
        return Exchange(ex.slot, nbr_id[q], nbr_slot[q], False, t)
    return ex


def _best(me: int, x: float, y: float, t: float, slot: int, asked: bool, nbr_id: IntSeq,
          nbr_x: FloatSeq, nbr_y: FloatSeq, nbr_slot: IntSeq, nbr_partner: IntSeq,
          nbr_other: IntSeq, offsets: np.ndarray, motion: np.ndarray, least: float) -> int:
    """The neighbour (its index; -1: none) with the largest gain above ``least`` [m^2] of
    those that ask robot ``me`` for its place ``slot`` (``asked``), or else of the free
    ones of higher id."""
    gx, gy = place(offsets, motion, slot, t)
    best, pick = least, -1
    for q in range(len(nbr_id)):
        if asked:
            candidate = nbr_partner[q] == me and nbr_other[q] == slot
        else:
            candidate = nbr_id[q] > me and nbr_partner[q] == NOBODY
        if candidate and nbr_slot[q] != NOBODY and nbr_slot[q] != slot:
            ox, oy = place(offsets, motion, nbr_slot[q], t)
            gain = exchange_gain(x, y, gx, gy, nbr_x[q], nbr_y[q], ox, oy)
            if gain > best:
                best, pick = gain, q
    return pick
