"""Seeded scenario families and micro cases: the situations users meet, as scenario documents.

:func:`family_doc` draws one scenario of a family (keys in :data:`FAMILY_KEYS`, described in
docs/families.md): robots scattered behind a band of obstacles, their formation's reference
beyond the band and moving away from it, the whole scene turned by a random angle.
:func:`micro_doc` draws one variation of a micro case (:mod:`hil.campaign.micro_cases`).
Both return the plain dictionary :func:`hil.files.scenario.parse_scenario` reads, without
[control], [robot] or [sim]; the result depends only on the arguments (the seed is mixed
with a CRC-32 of the family or case, never with Python's ``hash``). Bad arguments raise
:class:`hil.files.scenario.ScenarioError` naming ``where`` and the key.
"""
from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, fields
from typing import Any, Mapping

import numpy as np

from agent.config import ControlParams
from agent.formation import FormationKind, formation_offsets
from hil.campaign.micro_cases import CASES
from hil.campaign.scene import Scene
from hil.files.assignment import ASSIGN
from hil.files.scenario import ScenarioError

FAMILY_KEYS = {"kind", "robots", "spacing", "slots", "field", "speed", "assign"}
NOT_DRAWN = frozenset({"assign"})   # family keys that leave the drawn scene as it is
MICRO_CASES = ("head_on_swap", "offset_head_on", "obstacle_ahead", "crowd_onto_obstacle",
               "narrow_gap", "through_own_reference", "late_arrival")
KINDS = ("line", "wedge", "circle", "grid", "rotating_circle")
SLOTS = ("sorted", "shuffled")
FIELDS = ("sparse", "cluttered", "none")
ROBOTS = (5, 50)
RADII = (1.0, 3.0)           # m, obstacle radii
CHAIN_GAPS = (1.0, 3.5)      # m, surface gap between consecutive obstacles of a chain
OMEGA = (0.05, 0.1)          # rad/s, turn rate of rotating_circle (either sense)
EPS = 1e-3                   # m, kept inside every bound so that rounding cannot break it
DEFAULT_CONTROL = ControlParams()
AREA_PER_OBSTACLE = 150.0    # m^2 of field per disc (sparse) or chain (cluttered) aimed at
SLOT_SHARE = 0.5             # of a robot's top speed, the fastest its formation's slots move

Chain = list[tuple[float, float, float]]     # discs: x, y, radius [m]

assert set(MICRO_CASES) == set(CASES)


@dataclass(frozen=True)
class Family:
    """A validated family (defaults are the family's)."""

    kind: str = "line"
    robots: int = 10
    spacing: float = 5.0      # m, between neighbouring slots
    slots: str = "shuffled"
    field: str = "sparse"
    speed: float = 2.0        # m/s, of the formation's reference
    assign: str = "listed"    # [formation] assign of the scenario (not in the seed)

    def name(self, seed: int) -> str:
        """e.g. ``grid-20-cluttered-shuffled-s7`` (spacing and speed when not default)."""
        parts = [self.kind, str(self.robots), self.field, self.slots]
        if self.spacing != Family.spacing:
            parts.append(f"sp{self.spacing:g}")
        if self.speed != Family.speed:
            parts.append(f"v{self.speed:g}")
        if self.assign != Family.assign:
            parts.append(self.assign)
        return "-".join(parts + [f"s{seed}"])

    def canonical(self) -> str:
        """Stable text of the family, mixed into the seed: the drawn scene, so without
        ``assign`` (the same robots and slots, either assignment)."""
        return ";".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
                        if f.name not in NOT_DRAWN)


def parse_family(family: Mapping[str, Any], control: ControlParams = DEFAULT_CONTROL,
                 where: str = "family") -> Family:
    """Check a family's keys and values; fill in the defaults."""
    def fail(key: str, msg: str) -> ScenarioError:
        return ScenarioError(f"{where}: {key}: {msg}")

    if not isinstance(family, Mapping):
        raise ScenarioError(f"{where}: expected a table with keys among "
                            f"{', '.join(sorted(FAMILY_KEYS))}, got {family!r}")
    for key in family:
        if key not in FAMILY_KEYS:
            raise fail(str(key), f"unknown key; allowed: {', '.join(sorted(FAMILY_KEYS))}")
    d = Family()
    for key, allowed in (("kind", KINDS), ("slots", SLOTS), ("field", FIELDS),
                         ("assign", ASSIGN)):
        if family.get(key, getattr(d, key)) not in allowed:
            raise fail(key, f"expected one of {', '.join(allowed)}, got {family[key]!r}")
    robots = family.get("robots", d.robots)
    if isinstance(robots, bool) or not isinstance(robots, int) \
            or not ROBOTS[0] <= robots <= ROBOTS[1]:
        raise fail("robots", f"expected an integer {ROBOTS[0]}..{ROBOTS[1]}, got {robots!r}")
    need = control.b + control.hysteresis
    spacing = _number(family, "spacing", d.spacing, fail)
    if not spacing >= need + EPS:
        raise fail("spacing", f"must exceed b + hysteresis = {need:g} m (by 1 mm or more), "
                              f"got {spacing!r}")
    speed = _number(family, "speed", d.speed, fail)
    if not 0.0 <= speed < control.v_max:
        raise fail("speed", f"expected a number of m/s in [0, K*D_max = {control.v_max:g}), "
                            f"got {speed!r}")
    return Family(kind=family.get("kind", d.kind), robots=robots, spacing=spacing,
                  slots=family.get("slots", d.slots), field=family.get("field", d.field),
                  speed=speed, assign=family.get("assign", d.assign))


def _number(table: Mapping[str, Any], key: str, default: float, fail: Any) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value):
        raise fail(key, f"expected a finite number, got {value!r}")
    return float(value)


def _rng(seed: int, text: str, where: str) -> np.random.Generator:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ScenarioError(f"{where}: seed: expected a non-negative integer, got {seed!r}")
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(text.encode())]))


def _duration(duration: float, where: str) -> float:
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) \
            or not 0 < duration < math.inf:
        raise ScenarioError(f"{where}: duration: expected a positive number of seconds, "
                            f"got {duration!r}")
    return float(duration)


# --- families ---------------------------------------------------------------------------
def family_doc(family: Mapping[str, Any], seed: int, control: ControlParams = DEFAULT_CONTROL,
               duration: float = 40.0, where: str = "family",
               top_speed: float = math.inf) -> dict[str, Any]:
    """One scenario of ``family`` drawn with ``seed``, lasting ``duration`` [s], for robots
    of ``top_speed`` [m/s]: no slot of the formation moves faster than SLOT_SHARE of it
    (the reference's speed and turn rate are scaled down together), so that the robots can
    catch up with their slots and still have speed left to go round what is in the way."""
    duration = _duration(duration, where)
    fam, scene, angle = family_scene(family, seed, control, where)
    doc = scene.within(SLOT_SHARE * top_speed).rotated(angle).doc(fam.name(seed), duration)
    if fam.assign != Family.assign:
        doc["formation"]["assign"] = fam.assign
    return doc


def family_scene(family: Mapping[str, Any], seed: int, control: ControlParams = DEFAULT_CONTROL,
                 where: str = "family") -> tuple[Family, Scene, float]:
    """The family, its scene before the rotation (field ahead along +x), and the rotation
    angle [rad] that :func:`family_doc` applies."""
    fam = parse_family(family, control, where)
    rng = _rng(seed, fam.canonical(), where)
    scene = _family_scene(fam, rng, control)
    return fam, scene, float(rng.uniform(-math.pi, math.pi))


def _family_scene(fam: Family, rng: np.random.Generator, ctl: ControlParams) -> Scene:
    n, s = fam.robots, fam.spacing
    rotating = fam.kind == "rotating_circle"
    offsets = formation_offsets(FormationKind.CIRCLE if rotating else FormationKind(fam.kind),
                                n, s)
    omega = float(rng.uniform(*OMEGA) * rng.choice((-1.0, 1.0))) if rotating else 0.0
    if rotating:                                   # the slots sweep a disc
        reach = float(np.hypot(offsets[:, 0], offsets[:, 1]).max())
        rear, lateral = reach, np.array([-reach, reach])
    else:
        rear, lateral = float(-offsets[:, 0].min()), offsets[:, 1]
    width = max(float(np.ptp(lateral)) + s, 4 * s)          # m, start area across
    depth = max(2 * s, n * s * s / width)                   # m, one robot per spacing^2
    field_depth = max(5 * ctl.c, 10.0 + 0.6 * n)            # m, along the way
    half = max(width / 2, float(np.abs(lateral).max())) + ctl.c
    starts = _scatter(rng, n, (-ctl.c - depth, -ctl.c), width, ctl.b + ctl.hysteresis)
    headings = rng.uniform(-math.pi, math.pi, n)
    lo, hi = np.array([0.0, -half]), np.array([field_depth, half])
    count = max(2, round(field_depth * 2 * half / AREA_PER_OBSTACLE))
    if fam.field == "sparse":
        obstacles = _sparse(rng, lo, hi, 2 * ctl.c + EPS, count)
    elif fam.field == "cluttered":
        obstacles = [o for chain in chains(rng, lo, hi, ctl, count) for o in chain]
    else:
        obstacles = []
    if fam.slots == "sorted":      # lateral order of starts = lateral order of slots
        by_slot = np.lexsort((offsets[:, 0], offsets[:, 1]))
        slot_of = np.empty(n, int)
        slot_of[by_slot] = np.arange(n)
        picked = np.lexsort((starts[:, 0], starts[:, 1]))[slot_of]
    else:
        picked = rng.permutation(n)
    return Scene(poses=np.column_stack([starts[picked], headings]), offsets=offsets,
                 center0=np.array([field_depth + ctl.c + rear, 0.0]),
                 velocity=np.array([fam.speed, 0.0]), omega=omega,
                 obstacles=np.array(obstacles, dtype=float).reshape(-1, 3))


def _scatter(rng: np.random.Generator, n: int, xs: tuple[float, float], width: float,
             apart: float) -> np.ndarray:
    """n points in x in ``xs`` [m], |y| <= width/2, pairwise ``apart`` [m] or more (the
    area grows backwards while they do not fit)."""
    pts: list[np.ndarray] = []
    x0, x1 = xs
    while len(pts) < n:
        for _ in range(200 * n):
            p = rng.uniform((x0, -width / 2), (x1, width / 2))
            if all(math.dist(p, q) >= apart + EPS for q in pts):
                pts.append(p)
                if len(pts) == n:
                    break
        x0 -= 0.2 * (x1 - x0)
    return np.array(pts)


def _fits(centre: np.ndarray, r: float, placed: Chain, gap: float) -> bool:
    return all(math.dist(centre, o[:2]) - r - o[2] >= gap for o in placed)


def _disc(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, float]:
    r = float(rng.uniform(*RADII))
    return rng.uniform(lo + r, hi - r), r


def _inside(centre: np.ndarray, r: float, lo: np.ndarray, hi: np.ndarray) -> bool:
    return bool(np.all(centre - r >= lo) and np.all(centre + r <= hi))


def _sparse(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, gap: float,
            count: int) -> Chain:
    """Up to ``count`` discs inside the box lo..hi, surfaces ``gap`` [m] or more apart
    (the first of 30 count candidates that fit)."""
    tries = 30 * count
    r = rng.uniform(*RADII, tries)
    centres = lo + r[:, None] + rng.uniform(size=(tries, 2)) * (hi - lo - 2 * r[:, None])
    out = np.zeros((count, 3))
    k = 0
    for centre, radius in zip(centres, r):
        d = np.hypot(out[:k, 0] - centre[0], out[:k, 1] - centre[1])
        if (d - out[:k, 2] - radius >= gap).all():
            out[k] = (centre[0], centre[1], radius)
            k += 1
            if k == count:
                break
    return [(float(x), float(y), float(rr)) for x, y, rr in out[:k]]


def chains(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, ctl: ControlParams,
           count: int) -> list[Chain]:
    """Up to ``count`` chains of 2-5 discs inside lo..hi: consecutive surfaces CHAIN_GAPS
    apart, other discs of the chain 1 m or more, other chains 2c or more. A first chain
    across the middle can leave no room for another: the field is then drawn again (up to
    20 times) until it holds two chains."""
    found: list[Chain] = []
    for _ in range(20):
        found = _chain_field(rng, lo, hi, ctl, count)
        if len(found) >= min(2, count):
            break
    return found


def _chain_field(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray,
                 ctl: ControlParams, count: int) -> list[Chain]:
    found: list[Chain] = []
    placed: Chain = []
    for _ in range(50 * count):
        # mostly across the way (+x): walls with narrow gaps
        length, heading = int(rng.integers(2, 6)), float(rng.uniform(math.pi / 6,
                                                                     5 * math.pi / 6))
        centre, r = _disc(rng, lo, hi)
        chain: Chain = []
        while _fits(centre, r, placed, 2 * ctl.c + EPS) \
                and _fits(centre, r, chain[:-1], CHAIN_GAPS[0] + EPS):
            chain.append((float(centre[0]), float(centre[1]), r))
            if len(chain) == length:
                break
            heading += float(rng.uniform(-0.5, 0.5))
            r_next = float(rng.uniform(*RADII))
            gap = float(rng.uniform(CHAIN_GAPS[0] + EPS, CHAIN_GAPS[1] - EPS))
            centre = centre + (r + gap + r_next) * np.array([math.cos(heading),
                                                             math.sin(heading)])
            r = r_next
            if not _inside(centre, r, lo, hi):
                break
        if len(chain) >= 2:
            found.append(chain)
            placed += chain
            if len(found) == count:
                break
    return found


# --- micro cases ------------------------------------------------------------------------
def micro_doc(name: str, seed: int, control: ControlParams = DEFAULT_CONTROL,
              duration: float | None = None, where: str = "micro") -> dict[str, Any]:
    """One variation of micro case ``name`` drawn with ``seed``; ``duration`` [s] defaults
    to the case's."""
    scene, angle, default = micro_scene(name, seed, control, where)
    duration = _duration(default if duration is None else duration, where)
    return scene.rotated(angle).doc(f"{name}-s{seed}", duration)


def micro_scene(name: str, seed: int, control: ControlParams = DEFAULT_CONTROL,
                where: str = "micro") -> tuple[Scene, float, float]:
    """The case's scene before the rotation, the rotation angle [rad] and its default
    duration [s]."""
    if name not in CASES:
        raise ScenarioError(f"{where}: name: expected one of {', '.join(MICRO_CASES)}, "
                            f"got {name!r}")
    rng = _rng(seed, f"micro={name}", where)
    scene, default = CASES[name](rng, control)
    return scene, float(rng.uniform(-math.pi, math.pi)), default
