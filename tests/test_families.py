"""Seeded scenario families and micro cases (hil/campaign/families.py): valid scenario documents,
deterministic, holding the geometry they promise; and ``boundswarm generate``."""
import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from agent.config import ControlParams
from agent.formation import FormationKind, formation_offsets
from firmware_sim.batch import SimOptions, simulate
from hil.campaign.families import (
    CHAIN_GAPS,
    FIELDS,
    KINDS,
    MICRO_CASES,
    OMEGA,
    SLOT_SHARE,
    SLOTS,
    chains,
    family_doc,
    family_scene,
    micro_doc,
    micro_scene,
)
from hil.campaign.scene import rot, wrap
from hil.cli import main
from hil.files.robot_profile import load_robot_profile
from hil.files.scenario import ScenarioError, load_scenario, parse_scenario
from hil.files.toml_text import dumps

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

CTL = ControlParams()
A, B, C = CTL.a, CTL.b, CTL.c


def pair_distances(p: np.ndarray) -> np.ndarray:
    """(N, N) distances between points, inf on the diagonal."""
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    return d + np.diag(np.full(len(p), np.inf))


def surface_gaps(sc) -> np.ndarray:
    """(K, K) gaps between obstacle surfaces, inf on the diagonal."""
    r = sc.obstacles.radii
    return pair_distances(sc.obstacles.centers) - r[:, None] - r[None, :]


def segment_distance(p, q, x) -> float:
    """Distance from point x to the segment p-q."""
    p, q, x = map(np.asarray, (p, q, x))
    s = np.clip(np.dot(x - p, q - p) / np.dot(q - p, q - p), 0.0, 1.0)
    return float(np.linalg.norm(p + s * (q - p) - x))


def plain(value) -> bool:
    """Only what TOML writes: str, int, float, bool, lists and dicts of them."""
    if isinstance(value, dict):
        return all(isinstance(k, str) and plain(v) for k, v in value.items())
    if isinstance(value, list):
        return all(plain(v) for v in value)
    return type(value) in (str, int, float, bool)


# --- families ---------------------------------------------------------------------------
@pytest.mark.parametrize("kind, field, slots", list(itertools.product(KINDS, FIELDS, SLOTS)))
def test_every_family_is_a_valid_deterministic_scenario(kind, field, slots):
    family = {"kind": kind, "field": field, "slots": slots, "robots": 7}
    docs = [family_doc(family, seed) for seed in (0, 1, 2)]
    for seed, doc in enumerate(docs):
        sc = parse_scenario(doc, "test")
        assert len(sc.ids) == 7 and sc.duration == 40.0
        assert doc["name"] == f"{kind}-7-{field}-{slots}-s{seed}"
        assert set(doc) <= {"name", "duration", "formation", "robots", "obstacles"}
        assert ("obstacles" in doc) == (field != "none")
        assert plain(doc) and tomllib.loads(dumps(doc)) == doc
        assert family_doc(family, seed) == doc
    assert docs[0] != docs[1] != docs[2] != docs[0]


@pytest.mark.parametrize("kind, field, seed", [(k, f, s) for k in KINDS for f in FIELDS
                                               for s in (3, 4)])
def test_family_geometry(kind, field, seed):
    speed = 1.5
    doc = family_doc({"kind": kind, "field": field, "speed": speed}, seed, duration=30.0)
    sc = parse_scenario(doc, "test")
    starts = sc.poses[:, :2]
    assert pair_distances(starts).min() >= B
    slots0, _ = sc.formation.reference(0.0)
    velocity = np.array(sc.formation.velocity)
    assert np.linalg.norm(velocity) == pytest.approx(speed, abs=1e-3)
    if field == "none":
        assert len(sc.obstacles) == 0
        return
    assert sc.obstacles.radii.min() >= 1.0 and sc.obstacles.radii.max() <= 3.0
    assert sc.obstacles.clearance(starts).min() >= B
    for t in np.linspace(0.0, sc.duration, 31):          # slots clear all along their path
        assert sc.obstacles.clearance(sc.formation.reference(t)[0]).min() >= B
    # along the formation's velocity: starts, then the field, then the slots
    ahead = velocity / np.linalg.norm(velocity)
    near = (sc.obstacles.centers @ ahead - sc.obstacles.radii).min()
    far = (sc.obstacles.centers @ ahead + sc.obstacles.radii).max()
    assert (starts @ ahead).max() < near and (slots0 @ ahead).min() > far
    gaps = surface_gaps(sc)
    if field == "sparse":
        assert gaps.min() >= 2 * C
    else:                   # chains: no overlap, every disc within a chain gap of another
        assert gaps.min() >= CHAIN_GAPS[0]
        assert (gaps.min(axis=1) <= CHAIN_GAPS[1]).all()
        assert len(sc.obstacles) >= 4


def test_chains_have_their_gaps_and_keep_apart():
    rng = np.random.default_rng(0)
    found = chains(rng, np.array([0.0, -30.0]), np.array([30.0, 30.0]), CTL, 6)
    assert len(found) >= 3
    for chain in found:
        assert 2 <= len(chain) <= 5
        for (x0, y0, r0), (x1, y1, r1) in zip(chain, chain[1:]):
            assert CHAIN_GAPS[0] <= math.dist((x0, y0), (x1, y1)) - r0 - r1 <= CHAIN_GAPS[1]
    for one, other in itertools.combinations(found, 2):
        for (x0, y0, r0), (x1, y1, r1) in itertools.product(one, other):
            assert math.dist((x0, y0), (x1, y1)) - r0 - r1 >= 2 * C


def test_gaps_scale_with_the_controller():
    ctl = ControlParams(b=2.5, c=5.0)
    sc = parse_scenario(family_doc({"robots": 20}, 1, ctl), "test")
    assert surface_gaps(sc).min() >= 2 * ctl.c
    assert sc.obstacles.clearance(sc.poses[:, :2]).min() >= ctl.b
    assert pair_distances(sc.poses[:, :2]).min() >= ctl.b


@pytest.mark.parametrize("kind", KINDS)
def test_the_whole_scene_is_rotated(kind):
    family = {"kind": kind, "robots": 9, "field": "cluttered"}
    _, scene, angle = family_scene(family, 5)
    sc = parse_scenario(family_doc(family, 5), "test")
    named = FormationKind.CIRCLE if kind == "rotating_circle" else FormationKind(kind)
    assert np.allclose(scene.offsets, formation_offsets(named, 9, 5.0))
    assert scene.velocity.tolist() == [2.0, 0.0]          # before the rotation: along +x
    assert (scene.poses[:, 0].max() < scene.obstacles[:, 0].min()
            < scene.slots(0.0)[:, 0].min())
    if kind == "rotating_circle":
        assert OMEGA[0] <= abs(sc.formation.omega) <= OMEGA[1]
    else:
        assert sc.formation.omega == 0.0
    turn = rot(angle)
    assert abs(wrap(angle)) > 1e-3
    for t in (0.0, 3.7, 25.0):
        assert np.allclose(sc.formation.reference(t)[0], scene.slots(t) @ turn.T, atol=1e-3)
    assert np.allclose(sc.poses[:, :2], scene.poses[:, :2] @ turn.T, atol=1e-3)
    assert np.allclose(wrap(sc.poses[:, 2] - scene.poses[:, 2] - angle), 0.0, atol=1e-3)
    assert np.allclose(sc.obstacles.centers, scene.obstacles[:, :2] @ turn.T, atol=1e-3)


@pytest.mark.parametrize("robots", [5, 23, 50])
def test_robot_count_and_slot_order(robots):
    for seed in range(3):
        _, scene, _ = family_scene({"robots": robots, "slots": "sorted"}, seed)
        assert len(scene.poses) == robots
        # a line: robot i's start is the i-th from the right as its slot is
        assert (np.argsort(scene.poses[:, 1]) == np.argsort(scene.offsets[:, 1])).all()
    shuffled = [family_scene({"robots": robots}, seed)[1] for seed in range(3)]
    assert any((np.argsort(s.poses[:, 1]) != np.argsort(s.offsets[:, 1])).any()
               for s in shuffled)


def test_assign_keeps_the_scene_and_names_it():
    listed = family_doc({"kind": "grid", "robots": 9}, 4)
    shortest = family_doc({"kind": "grid", "robots": 9, "assign": "shortest"}, 4)
    assert shortest["name"] == "grid-9-sparse-shuffled-shortest-s4"
    assert shortest.pop("formation").pop("assign") == "shortest"
    assert "assign" not in listed.pop("formation")
    assert {**shortest, "name": listed["name"]} == listed


@pytest.mark.parametrize("family, message", [
    ({"colour": "red"}, "colour: unknown key"),
    ({"kind": "blob"}, "kind: expected one of line, wedge"),
    ({"robots": 3}, "robots: expected an integer 5..50, got 3"),
    ({"robots": 51}, "robots: expected an integer 5..50"),
    ({"robots": 7.0}, "robots: expected an integer"),
    ({"robots": True}, "robots: expected an integer"),
    ({"spacing": 2.5}, r"spacing: must exceed b \+ hysteresis = 2.5 m"),
    ({"spacing": "wide"}, "spacing: expected a finite number"),
    ({"slots": "random"}, "slots: expected one of sorted, shuffled"),
    ({"field": "dense"}, "field: expected one of sparse, cluttered, none"),
    ({"assign": "nearest"}, "assign: expected one of listed, shortest"),
    ({"speed": -1.0}, "speed: expected"),
    ({"speed": 12.0}, "speed: expected"),
])
def test_bad_family_keys_and_values_are_named(family, message):
    with pytest.raises(ScenarioError, match=f"^fam: {message}"):
        family_doc(family, 1, where="fam")


def test_bad_seed_duration_and_control_bound():
    with pytest.raises(ScenarioError, match="^family: seed"):
        family_doc({}, -1)
    with pytest.raises(ScenarioError, match="^family: duration"):
        family_doc({}, 1, duration=0.0)
    family_doc({"spacing": 3.0}, 1)
    with pytest.raises(ScenarioError, match=r"spacing: must exceed b \+ hysteresis = 3.5"):
        family_doc({"spacing": 3.0}, 1, ControlParams(b=3.0, c=5.0))


def test_a_small_family_converges_without_collision():
    sc = parse_scenario(family_doc({"robots": 6, "slots": "sorted"}, 1, duration=15.0), "t")
    res = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                   SimOptions(duration=sc.duration, sensing_range=sc.sensing_range,
                              record_every=0))
    m = res.metrics.summary(sc.name, sc.duration)
    assert m["collisions"] == 0 and m["converged"], m["stuck_robots"]
    assert m["min_pair_distance"] > A and A < m["min_obstacle_clearance"] < C  # field met


# --- micro cases ------------------------------------------------------------------------
@pytest.mark.parametrize("name", MICRO_CASES)
def test_every_micro_case_is_a_valid_deterministic_scenario(name):
    docs = [micro_doc(name, seed) for seed in range(4)]
    for seed, doc in enumerate(docs):
        sc = parse_scenario(doc, "test")
        assert 1 <= len(sc.ids) <= 9 and doc["name"] == f"{name}-s{seed}"
        assert plain(doc) and micro_doc(name, seed) == doc
        assert sc.duration == micro_scene(name, seed)[2]
        if len(sc.obstacles):
            assert sc.obstacles.clearance(sc.poses[:, :2]).min() >= B
            assert sc.obstacles.clearance(sc.formation.reference(0.0)[0]).min() >= B
        if len(sc.ids) > 1:
            assert pair_distances(sc.poses[:, :2]).min() >= B
    assert len({str(d) for d in docs}) == len(docs)
    assert micro_doc(name, 0, duration=7.0)["duration"] == 7.0


def micro(name: str, seed: int):
    sc = parse_scenario(micro_doc(name, seed), "test")
    return sc, sc.poses[:, :2], sc.formation.reference(0.0)[0]


@pytest.mark.parametrize("seed", range(5))
def test_micro_case_properties(seed):
    sc, p, s = micro("head_on_swap", seed)         # each one's slot is the other's start
    assert np.allclose(s, p[::-1], atol=1e-3)

    sc, p, s = micro("offset_head_on", seed)       # parallel, opposite, 0 < offset < b
    lateral = segment_distance(p[0], s[0], p[1])
    assert 0.2 * B - 1e-3 <= lateral <= 0.8 * B + 1e-3
    assert np.dot(s[0] - p[0], s[1] - p[1]) < 0

    sc, p, s = micro("obstacle_ahead", seed)       # the disc lies across the straight path
    assert len(p) == 1 and len(sc.obstacles) == 1
    assert segment_distance(p[0], s[0], sc.obstacles.centers[0]) < sc.obstacles.radii[0]

    sc, p, s = micro("crowd_onto_obstacle", seed)  # slots round one disc, behind it
    assert 4 <= len(p) <= 6 and len(sc.obstacles) == 1
    assert (sc.obstacles.clearance(s) <= C).all()
    o, r = sc.obstacles.centers[0], sc.obstacles.radii[0]
    assert any(segment_distance(a, b, o) < r + B for a, b in zip(p, s))   # blocked
    assert np.dot(s.mean(axis=0) - o, o - p.mean(axis=0)) > 0

    sc, p, s = micro("narrow_gap", seed)           # a < gap < 2b; one path through it
    gap = surface_gaps(sc)[0, 1]
    assert A < gap < 2 * B
    (o0, o1), r0 = sc.obstacles.centers, sc.obstacles.radii[0]
    crossing = [np.linalg.solve(np.column_stack([b - a, o0 - o1]), o0 - a)
                for a, b in zip(p, s)]              # (path, centre line) parameters
    assert any(0 < u < 1 and r0 < v * np.linalg.norm(o1 - o0) < r0 + gap
               for u, v in crossing)

    sc, p, s = micro("through_own_reference", seed)  # the reference runs through the robot
    ts = np.linspace(0.0, sc.duration, 601)
    track = np.array([sc.formation.reference(t)[0] for t in ts])      # (T, N, 2)
    assert (np.linalg.norm(s - p, axis=1) >= 2 * C).all()
    assert (np.linalg.norm(track - p, axis=2).min(axis=0) < B).all()

    sc, p, s = micro("late_arrival", seed)         # a formed grid, one robot far behind
    off = np.linalg.norm(p - s, axis=1)
    late = int(np.argmax(off))
    assert (np.delete(off, late) < 1e-3).all() and off[late] > 3 * 2 * (B + CTL.hysteresis)
    assert min(segment_distance(p[late], s[late], q)
               for q in np.delete(s, late, axis=0)) < B


def test_bad_micro_case_is_named():
    with pytest.raises(ScenarioError, match="^micro: name: expected one of head_on_swap"):
        micro_doc("pile_up", 1)


# --- boundswarm generate ----------------------------------------------------------------
def test_generate_writes_a_scenario_file(tmp_path, capsys):
    out = tmp_path / "g" / "family.toml"
    assert main(["generate", "--family", "kind=wedge, robots=8,field=cluttered,spacing=6",
                 "--seed", "3", "--out", str(out)]) == 0
    sc = load_scenario(out)
    want = parse_scenario(family_doc({"kind": "wedge", "robots": 8, "field": "cluttered",
                                      "spacing": 6}, 3), "t")
    assert sc.name == want.name == "wedge-8-cluttered-shuffled-sp6-s3"
    assert np.array_equal(sc.poses, want.poses)
    assert np.array_equal(sc.obstacles.centers, want.obstacles.centers)
    assert "wedge-8-cluttered-shuffled-sp6-s3" in capsys.readouterr().out

    out = tmp_path / "micro.toml"
    assert main(["generate", "--micro", "narrow_gap", "--seed", "2", "--out", str(out),
                 "--duration", "12"]) == 0
    assert load_scenario(out).duration == 12.0


def slot_speed(doc):
    """The fastest a slot of the scenario's formation moves [m/s]."""
    f = doc["formation"]
    reach = max(math.hypot(*o) for o in f["offsets"])
    return math.hypot(*f["velocity"]) + abs(f["omega"]) * reach


@pytest.mark.parametrize("kind", ["rotating_circle", "grid"])
@pytest.mark.parametrize("top", [1.5, 3.0, math.inf])
def test_slots_move_no_faster_than_the_robots_can_keep_up_with(kind, top):
    """A 20-robot circle turning at 0.05-0.1 rad/s while it moves at 2 m/s has slots faster
    than a 1.5 m/s robot: speed and turn rate are scaled down together to half its top
    speed; everything else (and any formation slow enough) is unchanged."""
    family = {"kind": kind, "robots": 20}
    free = family_doc(family, 4)
    bounded = family_doc(family, 4, top_speed=top)
    want = min(slot_speed(free), SLOT_SHARE * top)
    assert slot_speed(bounded) == pytest.approx(want, rel=1e-4)
    f, g = free["formation"], bounded["formation"]
    if kind == "rotating_circle" and top < math.inf:
        assert slot_speed(free) > SLOT_SHARE * top
        assert g["omega"] / f["omega"] == pytest.approx(g["velocity"][0] / f["velocity"][0],
                                                        rel=1e-3)
    assert {k: v for k, v in bounded.items() if k != "formation"} == \
        {k: v for k, v in free.items() if k != "formation"}


def test_generate_with_a_robot_profile(tmp_path):
    out, profile = tmp_path / "heavy.toml", Path(__file__).parent.parent / "robots/heavy.toml"
    assert main(["generate", "--family", "kind=rotating_circle,robots=20", "--seed", "1",
                 "--robot", str(profile), "--out", str(out)]) == 0
    sc = load_scenario(out)
    heavy = load_robot_profile(profile)
    assert sc.robot == heavy and sc.plant.value == "wheels"
    reach = np.hypot(*sc.formation.offsets.T).max()
    assert np.hypot(*sc.formation.velocity) + abs(sc.formation.omega) * reach == \
        pytest.approx(SLOT_SHARE * heavy.v_wheel_max, rel=1e-4)


def test_generate_help_names_every_micro_case(capsys):
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    text = capsys.readouterr().out
    assert all(name in text for name in MICRO_CASES)


@pytest.mark.parametrize("args, message", [
    (["--family", "robots=3"], "--family: robots: expected an integer 5..50, got 3"),
    (["--family", "robots"], "--family: expected KEY=VALUE"),
    (["--micro", "pile_up"], "--micro: name: expected one of"),
    (["--family", "", "--seed", "-2"], "--seed"),
])
def test_generate_refuses_bad_input(tmp_path, capsys, args, message):
    argv = ["generate", *args, "--out", str(tmp_path / "x.toml")]
    if "--seed" not in args:
        argv += ["--seed", "1"]
    assert main(argv) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x.toml").exists()
