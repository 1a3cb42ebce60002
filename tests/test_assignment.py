"""The assignment of robots to a formation's places as a set (hil/files/assignment.py)."""
import itertools

import numpy as np
import pytest

from hil.files.assignment import shortest_assignment


def total(starts, slots, perm):
    return float(((starts - slots[perm]) ** 2).sum())


@pytest.mark.parametrize("n", [1, 2, 3, 5, 7])
def test_it_finds_the_least_sum_of_squares(n):
    """Against every permutation, on seeded random scenes (also with tied costs)."""
    rng = np.random.default_rng(n)
    for _ in range(40):
        starts = rng.normal(size=(n, 2)) * 5
        slots = rng.normal(size=(n, 2)) * 5
        if n > 2:
            slots[1] = slots[0] + [0.0, 0.0] if rng.random() < 0.2 else slots[1]
        perm = shortest_assignment(starts, slots)
        assert sorted(perm.tolist()) == list(range(n))
        best = min(total(starts, slots, np.array(p)) for p in itertools.permutations(range(n)))
        assert total(starts, slots, perm) == pytest.approx(best, abs=1e-9)


def test_a_translation_of_the_places_keeps_the_assignment():
    rng = np.random.default_rng(3)
    starts, slots = rng.normal(size=(30, 2)) * 10, rng.normal(size=(30, 2)) * 10
    perm = shortest_assignment(starts, slots)
    assert (shortest_assignment(starts, slots + [250.0, -40.0]) == perm).all()


def test_robots_moving_in_step_keep_apart():
    """The CAPT property: no two robots gain by swapping, so robots moving in step along
    straight lines from their starts to their places stay at least 1/sqrt(2) of the smaller
    of their start and place separations apart."""
    rng = np.random.default_rng(5)
    starts, slots = rng.uniform(0, 10, (12, 2)), rng.uniform(5, 15, (12, 2))
    perm = shortest_assignment(starts, slots)
    goals = slots[perm]
    beta = np.linspace(0.0, 1.0, 201)[:, None]
    for i, j in itertools.combinations(range(12), 2):
        ds, dg = starts[i] - starts[j], goals[i] - goals[j]
        assert ds @ dg >= -1e-9
        gap = np.hypot(*((1 - beta) * ds + beta * dg).T).min()
        assert gap >= min(np.hypot(*ds), np.hypot(*dg)) / np.sqrt(2) - 1e-9


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match=r"starts \(3, 2\) and slots \(2, 2\)"):
        shortest_assignment(np.zeros((3, 2)), np.zeros((2, 2)))
