"""Which robot takes which slot: the formation's slots as a set (docs/formats.md).

A scenario lists one offset per robot; with ``[formation] assign = "shortest"`` the robots
instead take the slots that minimise the sum of the squared distances from their start to
their slot's reference at t = 0 (CAPT, Turpin, Michael and Kumar 2014). No two robots gain
by swapping slots, so robots driving in step along straight lines to them stay at least
1/sqrt(2) of the smaller of their start and slot separations apart; and the sum does not
change when the formation translates, so the assignment holds for a formation in motion.
It is made once, by whoever issues the mission: the scenario loader from the planned
starts (for the batch simulator and the SITL), ``boundswarm mission`` from where the
robots report they stand; agents receive their offset as before.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from agent.formation import Formation

ASSIGN = ("listed", "shortest")


def assigned(formation: Formation, starts: np.ndarray) -> Formation:
    """``formation`` with its places (a set) given to the robots at ``starts`` (N, 2) [m],
    in robot order, by :func:`shortest_assignment` against the places at t = 0."""
    slots = np.array([formation.point(i, 0.0)[:2] for i in range(len(formation.offsets))])
    return replace(formation, offsets=formation.offsets[shortest_assignment(starts, slots)])


def shortest_assignment(starts: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """``perm`` (N,): robot i at ``starts[i]`` [m] takes ``slots[perm[i]]`` [m], the
    assignment of least sum of squared distances (ties: the lower slot index first)."""
    starts, slots = np.asarray(starts, float), np.asarray(slots, float)
    if starts.shape != slots.shape or starts.ndim != 2:
        raise ValueError(f"assignment: starts {starts.shape} and slots {slots.shape} must "
                         f"both be (N, 2)")
    diff = starts[:, None, :] - slots[None, :, :]
    return _hungarian(np.einsum("ijk,ijk->ij", diff, diff))


def _hungarian(cost: np.ndarray) -> np.ndarray:
    """The row -> column assignment of least total ``cost`` (N, N): the Hungarian method
    with potentials, O(N^3), one row added at a time along a shortest augmenting path."""
    n = cost.shape[0]
    u, v = np.zeros(n + 1), np.zeros(n + 1)      # potentials of rows and columns
    row_of = np.zeros(n + 1, dtype=int)          # column j -> its row (1-based; 0: free)
    via = np.zeros(n + 1, dtype=int)             # column j -> previous column on the path
    for i in range(1, n + 1):
        row_of[0], j0 = i, 0
        reach = np.full(n + 1, math.inf)         # least reduced cost to each column
        used = np.zeros(n + 1, dtype=bool)
        while True:
            used[j0] = True
            i0 = row_of[j0]
            free = ~used[1:]
            reduced = cost[i0 - 1] - u[i0] - v[1:]
            better = free & (reduced < reach[1:])
            reach[1:][better] = reduced[better]
            via[1:][better] = j0
            step = np.where(free, reach[1:], math.inf)
            j1 = int(np.argmin(step)) + 1
            delta = step[j1 - 1]
            u[row_of[used]] += delta
            v[used] -= delta
            reach[1:][free] -= delta
            j0 = j1
            if row_of[j0] == 0:
                break
        while j0:                                # flip the path's assignments
            j1 = via[j0]
            row_of[j0] = row_of[j1]
            j0 = j1
    perm = np.empty(n, dtype=int)
    perm[row_of[1:] - 1] = np.arange(n)
    return perm
