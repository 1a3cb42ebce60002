"""A stand-in for hil.families (branch ``families``) in the campaign tests, until it lands.

Same interface: family_doc(family, seed, control, duration, where), micro_doc(name, seed,
control, duration, where), MICRO_CASES. Seeded random starts behind a formation moving +x,
with a few obstacles for field "sparse"/"cluttered".
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from agent.config import ControlParams
from hil.scenario import ScenarioError

MICRO_CASES = ("head_on_swap", "offset_head_on", "obstacle_ahead", "crowd_onto_obstacle",
               "narrow_gap", "through_own_reference", "late_arrival")
KINDS = ("line", "wedge", "circle", "grid", "rotating_circle")
FIELDS = ("sparse", "cluttered", "none")
DEFAULT = ControlParams()


def family_doc(family: Mapping[str, Any], seed: int, control: ControlParams = DEFAULT,
               duration: float = 40.0, where: str = "family") -> dict:
    unknown = set(family) - {"kind", "robots", "spacing", "slots", "field", "speed"}
    if unknown:
        raise ScenarioError(f"{where}: unknown key(s) {sorted(unknown)}")
    kind = family.get("kind", "line")
    if kind not in KINDS:
        raise ScenarioError(f"{where}: kind: expected one of {KINDS}, got {kind!r}")
    field = family.get("field", "none")
    if field not in FIELDS:
        raise ScenarioError(f"{where}: field: expected one of {FIELDS}, got {field!r}")
    n = int(family.get("robots", 5))
    if not 2 <= n <= 50:
        raise ScenarioError(f"{where}: robots: expected 2..50, got {n}")
    spacing = float(family.get("spacing", 5.0))
    speed = float(family.get("speed", 1.0))
    rng = np.random.default_rng(seed)
    robots: list[dict] = []
    while len(robots) < n:
        p = rng.uniform([-45.0, -15.0], [-25.0, 15.0])
        if all(math.dist(p, r["pose"][:2]) >= 2 * control.b for r in robots):
            robots.append({"id": len(robots) + 1,
                           "pose": [float(p[0]), float(p[1]), float(rng.uniform(-3, 3))]})
    obstacles = []
    if field != "none":
        for k in range(2 if field == "sparse" else 4):
            obstacles.append({"center": [10.0 + 12.0 * k, float(rng.uniform(-20, 20))],
                              "radius": float(rng.uniform(1.0, 2.0))})
    formation = {"kind": "circle" if kind == "rotating_circle" else kind, "spacing": spacing,
                 "center0": [-20.0, 0.0], "velocity": [speed, 0.0]}
    if kind == "rotating_circle":
        formation["omega"] = 0.1
    return {"name": f"{kind}-{n}-{field}-s{seed}", "duration": float(duration),
            "formation": formation, "robots": robots, "obstacles": obstacles}


def micro_doc(name: str, seed: int, control: ControlParams = DEFAULT,
              duration: float | None = None, where: str = "micro") -> dict:
    if name not in MICRO_CASES:
        raise ScenarioError(f"{where}: expected one of {MICRO_CASES}, got {name!r}")
    rng = np.random.default_rng(seed)
    jitter = float(rng.uniform(-0.5, 0.5))
    obstacles = [{"center": [0.0, 0.0], "radius": 2.0}] if "obstacle" in name else []
    return {"name": f"{name}-s{seed}", "duration": float(duration or 15.0),
            "formation": {"kind": "offsets", "center0": [0.0, 0.0],
                          "offsets": [[10.0, 0.0], [-10.0, 0.0]]},
            "robots": [{"id": 1, "pose": [-10.0, jitter, 0.0]},
                       {"id": 2, "pose": [10.0, -jitter, math.pi]}],
            "obstacles": obstacles}
