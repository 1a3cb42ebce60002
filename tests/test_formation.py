import math

import numpy as np
import pytest

from agent.formation import Formation, FormationKind, formation_offsets


def test_paper_line_formation():
    f = Formation(formation_offsets(FormationKind.LINE, 9, 4.0), (20.0, 0.0), (2.0, 0.0))
    for t in (0.0, 3.5, 20.0):
        p, v = f.reference(t)
        i = np.arange(1, 10)
        assert p[:, 0] == pytest.approx(2 * t + 20)
        assert p[:, 1] == pytest.approx(4 * i - 20)
        assert v == pytest.approx(np.tile([2.0, 0.0], (9, 1)))


@pytest.mark.parametrize("kind", [FormationKind.LINE, FormationKind.WEDGE,
                                  FormationKind.CIRCLE, FormationKind.GRID])
@pytest.mark.parametrize("n", [1, 2, 5, 9, 16])
def test_named_formations_are_centred_and_spaced(kind, n):
    off = formation_offsets(kind, n, 3.0)
    assert off.shape == (n, 2)
    assert off.mean(axis=0) == pytest.approx([0.0, 0.0], abs=1e-12)
    if n > 1:
        f = Formation(off, (0.0, 0.0))
        assert f.min_spacing() == pytest.approx(3.0)


def test_min_spacing_in_chunks_and_the_fastest_place():
    rng = np.random.default_rng(3)
    off = rng.uniform(-50.0, 50.0, (40, 2))
    d = np.linalg.norm(off[:, None] - off[None], axis=-1)
    want = d[~np.eye(40, dtype=bool)].min()
    f = Formation(off, (0.0, 0.0), (3.0, 4.0), omega=-0.1)
    assert f.min_spacing(chunk=7) == f.min_spacing() == pytest.approx(want)
    # the velocity's 5 m/s plus |omega| x the farthest place's distance from the centre
    assert f.pace == pytest.approx(5.0 + 0.1 * np.linalg.norm(off, axis=1).max())


def test_the_nearest_place_ahead_along_the_motion():
    """A line across the motion has no place ahead of another; a grid moving along its
    rows has one a spacing ahead; a ring turning about its centre, the next place along
    the ring; chunks change nothing (a place within 30 degrees of the velocity counts)."""
    line = formation_offsets(FormationKind.LINE, 5, 4.0)             # along y
    assert Formation(line, (0.0, 0.0), (2.0, 0.0)).min_ahead() == math.inf
    assert Formation(line, (0.0, 0.0), (0.0, 2.0)).min_ahead() == pytest.approx(4.0)
    assert Formation(line, (0.0, 0.0)).min_ahead() == math.inf       # it does not move
    grid = formation_offsets(FormationKind.GRID, 9, 5.0)
    moving = Formation(grid, (0.0, 0.0), (1.0, 1.0))                # along a diagonal
    assert moving.min_ahead() == pytest.approx(5.0 * math.sqrt(2.0))
    assert moving.min_ahead(chunk=2) == moving.min_ahead()
    ring = formation_offsets(FormationKind.CIRCLE, 20, 5.0)
    chord = float(np.linalg.norm(ring[0] - ring[1]))
    assert Formation(ring, (0.0, 0.0), omega=0.2).min_ahead() == pytest.approx(chord)


def test_rotating_formation_velocity_is_the_derivative():
    f = Formation(formation_offsets(FormationKind.CIRCLE, 6, 4.0), (1.0, 2.0), (0.5, -0.2),
                  omega=0.3)
    t, h = 2.0, 1e-6
    p1, v = f.reference(t)
    p2, _ = f.reference(t + h)
    assert (p2 - p1) / h == pytest.approx(v, abs=1e-5)
    # rigid: distances between references do not change
    d0 = np.linalg.norm(f.reference(0.0)[0][0] - f.reference(0.0)[0][3])
    assert np.linalg.norm(p1[0] - p1[3]) == pytest.approx(d0)


def test_offsets_kind_needs_explicit_offsets():
    with pytest.raises(ValueError, match="explicit offsets"):
        formation_offsets(FormationKind.OFFSETS, 3, 1.0)
    assert math.isinf(Formation(np.zeros((1, 2)), (0.0, 0.0)).min_spacing())


def test_point_is_one_robots_reference_and_velocity_in_floats():
    f = Formation(formation_offsets(FormationKind.WEDGE, 5, 3.0), (2.0, -1.0), (0.7, 0.2), 0.3)
    for t in (0.0, 1.3, 17.9):
        p, v = f.reference(t)
        for i in range(5):
            got = f.point(i, t)
            assert all(type(g) is float for g in got)
            assert got == (*p[i], *v[i])
