"""The place exchange's handshake (agent.exchange), one robot's step at a time."""
import math

import numpy as np
import pytest

from agent.exchange import HOLD as HOLD_LIMITS
from agent.exchange import NOBODY, Exchange, Heard, exchange_gain, exchange_step
from agent.formation import Places
from agent.neighbours import Reports

OFFSETS = np.array([[4.0, 0.0], [-4.0, 0.0], [0.0, 8.0]])    # places 0, 1, 2 [m]
MOTION = np.zeros(5)                                          # the places stand still
STALENESS = 0.5                                               # s
HOLD = HOLD_LIMITS * STALENESS                                # s, the handshake's hold


def reports(rows) -> Reports:
    """The reports of robots (id, x, y, slot, partner, other), heard at t = 10 s."""
    rows = list(rows)
    ints = [[int(r[c]) for r in rows] for c in (0, 3, 4, 5)]
    return Reports(ints[0], [10.0] * len(rows), [float(r[1]) for r in rows],
                   [float(r[2]) for r in rows], [0.0] * len(rows), [0.0] * len(rows),
                   [0.0] * len(rows), ints[1], ints[2], ints[3])


def step(me, xy, ex, nbrs, t=10.0, gain_min=1.0, motion=MOTION):
    """Robot ``me`` at ``xy`` hearing ``nbrs``: (id, x, y, slot, partner, other) rows, all
    fresh and in range, the row of its partner (if any) also as the partner's newest
    state, heard now; the formation moving as ``motion``."""
    rep = reports(nbrs)
    ids = list(rep.robot)
    pal = ids.index(ex.partner) if ex.partner in ids else -1
    heard = Heard(rep, list(range(len(nbrs))), rep.x, rep.y, len(nbrs), pal,
                  0.0 if pal >= 0 else math.inf)
    return exchange_step(me, xy[0], xy[1], t, ex, heard, Places(OFFSETS, motion), gain_min,
                         STALENESS)


def test_the_gain_is_the_fall_of_the_squared_distances():
    p_i, g_i, p_j, g_j = np.array([-4.0, 1]), np.array([4.0, 0]), np.array([4.0, 2]), \
        np.array([-4.0, 0])
    before = np.sum((p_i - g_i) ** 2) + np.sum((p_j - g_j) ** 2)
    after = np.sum((p_i - g_j) ** 2) + np.sum((p_j - g_i) ** 2)
    assert exchange_gain(*p_i, *g_i, *p_j, *g_j) == pytest.approx(before - after)


def test_the_gain_takes_the_places_where_a_moving_formation_has_them():
    # at t = 10 s a formation centred at (20, 0), turning at pi/20 rad/s, has turned its
    # places 0 and 1 a quarter turn: place 0 at (20, 4), place 1 at (20, -4)
    turning = np.array([0.0, 0.0, 2.0, 0.0, math.pi / 20.0])
    ex = step(0, (20.0, -4.0), Exchange(0), [(1, 20.0, 4.0, 1, NOBODY, NOBODY)],
              motion=turning)
    assert ex == Exchange(0, 1, 1, False, 10.0)      # each stands at the other's place
    stay = step(0, (20.0, 4.0), Exchange(0), [(1, 20.0, -4.0, 1, NOBODY, NOBODY)],
                motion=turning)
    assert stay == Exchange(0)                       # each at its own: nothing to gain


def test_a_robot_asks_the_neighbour_of_higher_id_standing_at_its_place():
    ex = step(0, (-4.0, 0.0), Exchange(0), [(1, 4.0, 0.0, 1, NOBODY, NOBODY)])
    assert ex == Exchange(0, 1, 1, False, 10.0)
    # the robot of higher id waits to be asked
    assert step(1, (4.0, 0.0), Exchange(1), [(0, -4.0, 0.0, 0, NOBODY, NOBODY)]) == Exchange(1)


def test_no_ask_below_the_least_gain_or_to_a_busy_neighbour():
    near = [(1, 0.03125, 0.0, 1, NOBODY, NOBODY)]      # with robot 0 at (0, 0): 0.5 m^2
    assert step(0, (0.0, 0.0), Exchange(0), near, gain_min=1.0) == Exchange(0)
    assert step(0, (0.0, 0.0), Exchange(0), near, gain_min=0.4).partner == 1
    busy = [(1, 4.0, 0.0, 1, 2, 2)]
    assert step(0, (-4.0, 0.0), Exchange(0), busy) == Exchange(0)
    assert step(0, (-4.0, 0.0), Exchange(0), [(1, 4.0, 0.0, 1, NOBODY, NOBODY)],
                gain_min=0.0) == Exchange(0)                              # exchange off


def test_asked_a_robot_gives_its_place_when_its_own_data_shows_a_gain():
    asker = [(0, -4.0, 0.0, 0, 1, 1)]
    assert step(1, (4.0, 0.0), Exchange(1), asker) == Exchange(0, 0, 1, True, 10.0)
    # on its own data the asker stands where it would lose: no give
    far = [(0, 4.0, 6.0, 0, 1, 1)]
    assert step(1, (4.0, 0.0), Exchange(1), far) == Exchange(1)
    # an ask for another place is no ask for its own
    assert step(1, (4.0, 0.0), Exchange(1), [(0, -4.0, 0.0, 0, 1, 2)]) == Exchange(1)


def test_the_asker_takes_the_place_given_and_the_giver_frees_itself():
    asking = Exchange(0, 1, 1, False, 9.0)
    gave = [(1, 4.0, 0.0, 0, 0, 1)]                        # robot 1 holds place 0 now
    assert step(0, (-4.0, 0.0), asking, gave) == Exchange(1, NOBODY, NOBODY, False, 10.0)
    giving = Exchange(0, 0, 1, True, 9.5)
    still = [(0, -4.0, 0.0, 0, 1, 1)]                      # not taken yet
    assert step(1, (4.0, 0.0), giving, still) == giving
    taken = [(0, -4.0, 0.0, 1, NOBODY, NOBODY)]
    assert step(1, (4.0, 0.0), giving, taken) == Exchange(0, NOBODY, NOBODY, False, 10.0)


def test_a_giver_waits_a_hold_for_a_silent_asker():
    giving = Exchange(0, 0, 1, True, 9.5)
    assert step(1, (4.0, 0.0), giving, [], t=10.0) == giving
    assert step(1, (4.0, 0.0), giving, [], t=10.6) == Exchange(0, NOBODY, NOBODY, False, 10.6)


def test_an_asker_gives_up_on_a_silent_or_busy_partner_then_waits_a_hold():
    asking = Exchange(0, 1, 1, False, 9.5)
    assert step(0, (-4.0, 0.0), asking, []) == asking          # silent for a moment: wait
    assert step(0, (-4.0, 0.0), asking, [], t=10.6) == Exchange(0, NOBODY, NOBODY, False,
                                                                 10.6)
    busy = [(1, 4.0, 0.0, 1, 2, 2)]
    gave_up = step(0, (-4.0, 0.0), asking, busy)
    assert gave_up == Exchange(0, NOBODY, NOBODY, False, 10.0)
    free = [(1, 4.0, 0.0, 1, NOBODY, NOBODY)]
    assert step(0, (-4.0, 0.0), gave_up, free, t=10.5) == gave_up      # within the hold
    assert step(0, (-4.0, 0.0), gave_up, free, t=11.0).partner == 1
    # no give within a hold of asking: give up
    assert step(0, (-4.0, 0.0), asking, free, t=10.51) == Exchange(0, NOBODY, NOBODY, False,
                                                                   10.51)


def test_a_give_heard_after_giving_up_still_completes_the_exchange():
    gave_up = Exchange(0, NOBODY, NOBODY, False, 9.9)
    late = [(1, 4.0, 0.0, 0, 0, 1)]                        # robot 1 gave: it names robot 0
    assert step(0, (-4.0, 0.0), gave_up, late) == Exchange(1, NOBODY, NOBODY, False, 10.0)


def test_a_giver_takes_its_place_back_when_the_asker_stayed_and_no_longer_asks():
    giving = Exchange(0, 0, 1, True, 9.9)
    stayed = [(0, -4.0, 0.0, 0, NOBODY, NOBODY)]          # robot 0 still at place 0
    assert step(1, (4.0, 0.0), giving, stayed) == Exchange(1, NOBODY, NOBODY, False, 10.0)
    moved_on = [(0, -4.0, 0.0, 2, NOBODY, NOBODY)]        # robot 0 took place 2 meanwhile
    assert step(1, (4.0, 0.0), giving, moved_on) == Exchange(0, NOBODY, NOBODY, False, 10.0)


def test_the_partners_newest_state_counts_out_of_range():
    """The asker hears its partner give by the partner's newest state, even one out of
    sensing range (not among the fresh neighbours)."""
    asking = Exchange(0, 1, 1, False, 9.8)
    far = reports([(1, 40.0, 0.0, 0, 0, 1)])            # robot 1, in place 0, 0.6 s ago
    heard = Heard(far, [], [], [], 0, 0, 0.6)
    ex = exchange_step(0, -4.0, 0.0, 10.0, asking, heard, Places(OFFSETS, MOTION), 1.0,
                       STALENESS)
    assert ex == Exchange(1, NOBODY, NOBODY, False, 10.0)


def test_of_two_robots_in_one_place_the_higher_id_takes_the_nearest_free_one():
    """Robots 0 and 1 both hold place 0 (an exchange left half done); robot 2 holds place
    2: robot 1 takes place 1, the only one free, and robot 0 keeps place 0."""
    free = Exchange(0, NOBODY, NOBODY, False, 5.0)
    heard = [(0, -4.0, 0.0, 0, NOBODY, NOBODY), (2, 0.0, 8.0, 2, NOBODY, NOBODY)]
    assert step(1, (4.0, 0.0), free, heard) == Exchange(1, NOBODY, NOBODY, False, 10.0)
    heard = [(1, 4.0, 0.0, 0, NOBODY, NOBODY), (2, 0.0, 8.0, 2, NOBODY, NOBODY)]
    assert step(0, (-4.0, 0.0), free, heard, gain_min=0.0) == free
    # no place free (robot 3 holds place 2): it stays
    heard = [(0, -4.0, 0.0, 0, NOBODY, NOBODY), (2, 0.0, 8.0, 1, NOBODY, NOBODY),
             (3, 9.0, 9.0, 2, NOBODY, NOBODY)]
    assert step(1, (4.0, 0.0), free, heard, gain_min=0.0) == free


def test_a_robot_s_own_report_holds_no_place_for_it():
    """Robot 1's own report (an old one, naming place 1) is passed over: place 1 is free
    for it to take when robot 0 holds its place 0 too."""
    free = Exchange(0, NOBODY, NOBODY, False, 5.0)
    heard = [(0, -4.0, 0.0, 0, NOBODY, NOBODY), (2, 0.0, 8.0, 2, NOBODY, NOBODY),
             (1, 4.0, 0.0, 1, NOBODY, NOBODY)]                  # its own, from before
    assert step(1, (4.0, 0.0), free, heard) == Exchange(1, NOBODY, NOBODY, False, 10.0)
