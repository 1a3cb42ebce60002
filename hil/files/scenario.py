"""Scenario files (TOML): robots, formation, obstacles, controller and robot parameters.

Format (every field, with its unit and default, in docs/formats.md)::

    name = "paper"
    duration = 20.0                 # s
    [control]                       # agent.config.ControlParams, all optional
    [robot]                         # agent.config.RobotParams, all optional
    [sim]                           # sensing_range (m, default 2c), substeps, plant
    [formation]                     # kind, spacing, center0, velocity, omega, offsets, assign
    [[robots]]                      # id, pose = [x, y, theta], in formation order
    [[obstacles]]                   # center = [x, y], radius
    [world]                         # firmware_sim.world.WorldParams, optional (ideal)
    [mocap]                         # firmware_sim.mocap_sim.MocapParams, optional
                                    # pose fixes (absent: the agents have odometry alone)

Every problem is reported as :class:`ScenarioError` naming the file and the field.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agent.config import ControlParams, RobotParams
from agent.envelope import SpeedEnvelope, speed_envelope
from agent.formation import Formation, FormationKind, formation_offsets
from common.schema import ConfigError, TableReader, from_table, load_toml
from firmware_sim.mocap_sim import MocapParams
from firmware_sim.plant import PlantKind
from firmware_sim.world import Obstacles, WorldParams
from hil.files.assignment import ASSIGN, assigned


class ScenarioError(ValueError):
    """A scenario file is unreadable, or a field in it is missing or wrong."""


@dataclass(frozen=True)
class Scenario:
    name: str
    duration: float             # s
    control: ControlParams
    robot: RobotParams
    formation: Formation
    ids: np.ndarray             # (N,) int
    poses: np.ndarray           # (N, 3) m, m, rad
    obstacles: Obstacles
    sensing_range: float        # m
    substeps: int
    plant: PlantKind
    world: WorldParams = WorldParams()
    source: Path | None = None
    robot_given: bool = False   # the file has a [robot] table (else RobotParams' defaults)
    mocap: MocapParams | None = None   # a simulated motion-capture system
    assign: str = "listed"      # [formation] assign: how the places were given (assignment.py)

    def envelope(self) -> SpeedEnvelope:
        """What the safety governor allows this scenario's robot (agent.config.
        speed_envelope) at its formation's pace, with neighbour data a link delay and a
        period old."""
        return speed_envelope(self.control, self.robot, self.sensing_range,
                              self.world.link_delay + self.control.period, self.formation.pace)

    def pace_held(self, envelope: SpeedEnvelope) -> bool:
        """Whether no place lies closer behind another, along the formation's motion,
        than ``envelope``'s following gap: else the rear place's robot trails it."""
        return bool(self.formation.min_ahead() >= envelope.follow)


TOP_KEYS = {"name", "duration", "control", "robot", "sim", "formation", "robots", "obstacles",
            "world", "mocap"}


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file."""
    path = Path(path)
    return parse_scenario(load_toml(path, "scenario file", ScenarioError), str(path),
                          source=path)


def parse_scenario(doc: dict[str, Any], where: str, source: Path | None = None) -> Scenario:
    """Validate a scenario already parsed from TOML; ``where`` names it in messages."""
    rd = TableReader(where, ScenarioError)
    rd.only(doc, TOP_KEYS, "top level")
    name = doc.get("name")
    if not isinstance(name, str) or not name:
        raise rd.fail("name", f"expected a non-empty string, got {name!r}")
    duration = rd.number(doc, "duration", "duration", positive=True)
    try:
        control = from_table(ControlParams, rd.table(doc, "control"), f"{where} [control]")
        robot = from_table(RobotParams, rd.table(doc, "robot"), f"{where} [robot]")
        world = from_table(WorldParams, rd.table(doc, "world"), f"{where} [world]")
        mocap = (from_table(MocapParams, rd.table(doc, "mocap"), f"{where} [mocap]")
                 if "mocap" in doc else None)
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None

    robots = rd.array_of_tables(doc, "robots", required=True)
    ids, poses = [], []
    for i, r in enumerate(robots):
        field = f"robots[{i}]"
        rd.only(r, {"id", "pose"}, field)
        rid = r.get("id")
        if isinstance(rid, bool) or not isinstance(rid, int) or rid < 0:
            raise rd.fail(f"{field}.id", f"expected a non-negative integer, got {rid!r}")
        if rid in ids:
            raise rd.fail(f"{field}.id", f"duplicate robot id {rid}")
        ids.append(rid)
        poses.append(rd.vector(r, "pose", f"{field}.pose", 3))

    for i, kill in enumerate(world.kill):
        if kill.robot not in ids:
            raise rd.fail(f"[world.kill][{i}].robot", f"no robot {kill.robot} in [[robots]]")
    for i, out in enumerate(mocap.outage if mocap is not None else ()):
        if out.robot not in ids:
            raise rd.fail(f"[mocap.outage][{i}].robot", f"no robot {out.robot} in [[robots]]")
    starts = np.array(poses, dtype=float).reshape(-1, 3)
    formation, assign = _formation(rd, rd.table(doc, "formation"), starts, control)

    obs = rd.array_of_tables(doc, "obstacles", required=False)
    centers, radii = [], []
    for i, o in enumerate(obs):
        field = f"obstacles[{i}]"
        rd.only(o, {"center", "radius"}, field)
        centers.append(rd.vector(o, "center", f"{field}.center", 2))
        radii.append(rd.number(o, "radius", f"{field}.radius", positive=True))
    obstacles = Obstacles(np.array(centers, dtype=float).reshape(-1, 2),
                          np.array(radii, dtype=float))

    sim = rd.table(doc, "sim")
    rd.only(sim, {"sensing_range", "substeps", "plant"}, "[sim]")
    sensing = rd.number(sim, "sensing_range", "[sim] sensing_range", default=2.0 * control.c,
                        positive=True)
    if sensing < 2.0 * control.c:
        raise rd.fail("[sim] sensing_range", f"must be >= 2c = {2 * control.c:g} m "
                                             f"(ROTATE looks 2c ahead), got {sensing:g}")
    substeps = sim.get("substeps", 4)
    if isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1:
        raise rd.fail("[sim] substeps", f"expected a positive integer, got {substeps!r}")
    try:
        plant = PlantKind(sim.get("plant", "ideal"))
    except ValueError:
        raise rd.fail("[sim] plant", f"expected one of {[k.value for k in PlantKind]}, "
                                     f"got {sim.get('plant')!r}") from None

    return Scenario(name=name, duration=duration, control=control, robot=robot,
                    formation=formation, ids=np.array(ids, dtype=int),
                    poses=starts, obstacles=obstacles,
                    sensing_range=sensing, substeps=substeps, plant=plant, world=world,
                    source=source, robot_given="robot" in doc, mocap=mocap, assign=assign)


def _formation(rd: TableReader, table: dict, poses: np.ndarray,
               control: ControlParams) -> tuple[Formation, str]:
    """The formation of robots starting at ``poses`` (N, 3), each robot with its listed
    offset or, with ``assign = "shortest"``, the slot of :mod:`hil.files.assignment`; and that
    ``assign``."""
    rd.only(table, {"kind", "spacing", "center0", "velocity", "omega", "offsets", "assign"},
            "[formation]")
    n = len(poses)
    assign = table.get("assign", ASSIGN[0])
    if assign not in ASSIGN:
        raise rd.fail("[formation] assign", f"expected one of {list(ASSIGN)}, got {assign!r}")
    try:
        kind = FormationKind(table.get("kind", "line"))
    except ValueError:
        raise rd.fail("[formation] kind", f"expected one of "
                      f"{[k.value for k in FormationKind]}, got {table.get('kind')!r}") from None
    if kind is FormationKind.OFFSETS:
        raw = table.get("offsets")
        if not isinstance(raw, list) or len(raw) != n:
            raise rd.fail("[formation] offsets", f"expected one [x, y] per robot ({n}), "
                                                 f"got {raw!r}")
        offsets = np.array([rd.vector({"o": o}, "o", f"[formation] offsets[{i}]", 2)
                            for i, o in enumerate(raw)])
    else:
        if "offsets" in table:
            raise rd.fail("[formation] offsets", "only allowed with kind = \"offsets\"")
        spacing = rd.number(table, "spacing", "[formation] spacing", default=4.0,
                            positive=True)
        offsets = formation_offsets(kind, n, spacing)
    formation = Formation(
        offsets=offsets,
        center0=rd.vector2(table, "center0", "[formation] center0", default=(0.0, 0.0)),
        velocity=rd.vector2(table, "velocity", "[formation] velocity", default=(0.0, 0.0)),
        omega=rd.number(table, "omega", "[formation] omega", default=0.0))
    if assign == "shortest" and n:
        formation = assigned(formation, poses[:, :2])
    need = control.b + control.hysteresis
    if formation.min_spacing() <= need:
        raise rd.fail("[formation]", f"two places are {formation.min_spacing():.3g} m apart; "
                                     f"they must be more than b + hysteresis = {need:g} m "
                                     f"apart or the robots never stop avoiding each other")
    return formation, assign
