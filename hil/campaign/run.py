"""One run of a campaign: its description -> a scenario -> the batch simulator -> one row.

:func:`run_one` is a pure function of the description (what :mod:`hil.campaign.spec`
expands a spec into), so a row is the same on any worker; it never raises: a run that fails
is a row with ``status = "failed"`` and the error in one line. :func:`scenario_doc` builds
the run's complete scenario (a TOML-able doc), which ``--replay`` writes and simulates with
``boundswarm sim``.
"""
from __future__ import annotations

import math
import os
import socket
import time
from typing import Any, Mapping

import numpy as np

from agent.config import ControlParams, RobotParams
from common.schema import from_table
from hil.campaign.spec import families_module, run_key

SWEPT_PREFIXES = ("family_", "world_", "control_")


def scenario_doc(desc: Mapping[str, Any]) -> dict[str, Any]:
    """The complete scenario of a run: the family's (or micro case's) doc with the run's
    [control], [robot] (and the wheels plant), [world] (its kill drawn from the world
    seed) and [mocap]."""
    control = from_table(ControlParams, desc["control"], "[control]")
    families = families_module()
    kwargs: dict[str, Any] = {"control": control}
    if desc.get("duration") is not None:
        kwargs["duration"] = desc["duration"]
    if "micro" in desc:
        doc = dict(families.micro_doc(desc["micro"], desc["seed"], **kwargs))
    else:
        if desc.get("robot") is not None:       # slots the profile's robots can keep up with
            kwargs["top_speed"] = from_table(RobotParams, desc["robot"], "[robot]").v_wheel_max
        doc = dict(families.family_doc(desc["family"], desc["seed"], **kwargs))
    if desc["control"]:
        doc["control"] = dict(desc["control"])
    if desc.get("robot") is not None:
        doc["robot"] = dict(desc["robot"])
        doc["sim"] = {**doc.get("sim", {}), "plant": "wheels"}
    if desc.get("world"):
        world = dict(desc["world"])
        kill_at = desc.get("kill_at")
        if kill_at:
            rng = np.random.default_rng([world["seed"], 2])
            ids = [r["id"] for r in doc["robots"]]
            robot = ids[int(rng.integers(len(ids)))]
            at = float(rng.uniform(kill_at[0], kill_at[1]))
            world["kill"] = [{"robot": robot, "at": round(at, 3)}]
        doc["world"] = world
    if desc.get("mocap"):
        doc["mocap"] = dict(desc["mocap"])
    return doc


def description_columns(desc: Mapping[str, Any]) -> dict[str, Any]:
    """The run's spec values as flat columns: family_*, micro, seed, profile, world_*
    (world_seed included), kill, control_*."""
    row: dict[str, Any] = {f"family_{k}": v for k, v in desc.get("family", {}).items()}
    if "micro" in desc:
        row["micro"] = desc["micro"]
    row["seed"] = desc["seed"]
    row["profile"] = desc["profile"]
    row.update({f"world_{k}": v for k, v in (desc.get("world") or {}).items()})
    row["kill"] = bool(desc.get("kill_at"))
    row.update({f"control_{k}": v for k, v in desc["control"].items()})
    return row


def is_safe(metrics: Mapping[str, Any], a: float) -> bool:
    """No pair closer than a and no robot centre within a of an obstacle surface (a
    distance never observed is safe)."""
    d, c = metrics.get("min_pair_distance"), metrics.get("min_obstacle_clearance")
    return (d is None or d > a) and (c is None or c > a)


def run_one(desc: Mapping[str, Any]) -> dict[str, Any]:
    """Simulate the run and return its row: key, status, error, the description's columns,
    the kill, a (collision distance), safe, deadlock and
    every key of the metrics summary."""
    row: dict[str, Any] = {"key": run_key(desc), "status": "ok", "error": None,
                           **description_columns(desc)}
    try:
        row.update(_simulate(desc, row["key"]))
    except Exception as exc:        # a run's failure is its row, not the campaign's
        row["status"] = "failed"
        row["error"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"[:500]
    return row


def _simulate(desc: Mapping[str, Any], key: str) -> dict[str, Any]:
    from firmware_sim.batch import SimOptions, simulate
    from firmware_sim.plant import PlantKind
    from hil.files.scenario import parse_scenario
    doc = scenario_doc(desc)
    sc = parse_scenario(doc, f"run {key}")
    # as sim: a world with wheel slip or encoder noise needs the wheels plant
    plant = PlantKind.WHEELS if sc.world.odometry else sc.plant
    options = SimOptions(duration=sc.duration, sensing_range=sc.sensing_range,
                         substeps=sc.substeps, plant=plant, record_every=0)
    result = simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                      options, world=sc.world, mocap=sc.mocap)
    metrics = result.metrics.summary(sc.name, options.duration)
    kill = (doc.get("world") or {}).get("kill") or [{}]
    # as sim warns (hil.cli.sim.state_envelope: not on the ideal plant)
    held = sc.pace_held(sc.envelope()) if plant is PlantKind.WHEELS else None
    out: dict[str, Any] = {
        "kill_robot": kill[0].get("robot"), "kill_time": kill[0].get("at"),
        "a": sc.control.a, "safe": is_safe(metrics, sc.control.a),
        "deadlock": bool(metrics["deadlocked"]) if "deadlocked" in metrics
        else not metrics["converged"],
        "pace_held": held}
    out.update(metrics)
    return out


def run_timed(desc: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """:func:`run_one` and its timing (wall and CPU seconds, host, process): what workers
    run."""
    started, cpu = time.perf_counter(), time.process_time()
    row = run_one(desc)
    return row, {"key": row["key"], "seconds": round(time.perf_counter() - started, 4),
                 "cpu_seconds": round(time.process_time() - cpu, 4),
                 "host": socket.gethostname(), "pid": os.getpid()}


def warm_up() -> float:
    """Load (or compile) the batch simulator's kernels in this process: two robots for a few
    periods in the ideal world and in one with every imperfection (a kill too), on each
    plant; returns the seconds it took."""
    from agent.config import RobotParams
    from agent.formation import Formation
    from firmware_sim import compiled
    from firmware_sim.batch import SimOptions, simulate
    from firmware_sim.plant import PlantKind
    from firmware_sim.world import Kill, Obstacles, WorldParams
    started = time.perf_counter()
    if not compiled.available():
        return 0.0
    control = ControlParams()
    formation = Formation(np.array([[0.0, -5.0], [0.0, 5.0]]), (0.0, 0.0), (1.0, 0.0))
    obstacles = Obstacles(np.array([[20.0, 0.0]]), np.array([1.0]))
    poses = np.array([[-5.0, -5.0, 0.0], [-5.0, 5.0, math.pi]])
    link: dict[str, Any] = {"link_delay": 0.05, "link_jitter": 0.01, "link_loss": 0.2,
                            "loss_burst": 2.0, "detection_noise": 0.01,
                            "detection_dropout": 0.1,
                            "kill": (Kill(robot=2, at=2 * control.period),)}
    worlds = ((PlantKind.IDEAL, WorldParams()), (PlantKind.IDEAL, WorldParams(**link)),
              (PlantKind.WHEELS, WorldParams()),
              (PlantKind.WHEELS, WorldParams(wheel_slip=0.02, encoder_noise=0.001, **link)))
    for plant, world in worlds:
        simulate(np.array([1, 2]), poses, formation, obstacles, control, RobotParams(),
                 SimOptions(duration=5 * control.period, plant=plant, record_every=0),
                 world=world)
    return time.perf_counter() - started
