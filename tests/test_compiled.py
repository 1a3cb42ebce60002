"""The batch simulator compiled with numba runs exactly what it runs interpreted: the same
source (agent.law and firmware_sim.swarm_step), bit for bit."""
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import model

from agent.config import ControlParams, RobotParams
from agent.formation import Formation, FormationKind, formation_offsets
from firmware_sim import compiled
from firmware_sim.batch import SimOptions, simulate
from firmware_sim.plant import PlantKind
from firmware_sim.world import Kill, Obstacles, WorldParams
from hil.files.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


def both(ids, poses, form, obstacles, robot=None, world=None, **options):
    return [simulate(ids, poses, form, obstacles, ControlParams(), robot or RobotParams(),
                     SimOptions(compiled=flag, **options), world=world)
            for flag in (False, True)]


def assert_equal_runs(a, b):
    for name in ("t", "pose", "v", "u", "mode", "ref"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.metrics.summary("x", 1.0) == b.metrics.summary("x", 1.0)
    assert a.metrics.geometry_dmin == b.metrics.geometry_dmin


def test_paper_example_compiled_equals_interpreted():
    sc = load_scenario(SCENARIOS / "paper.toml")
    a, b = both(sc.ids, sc.poses, sc.formation, sc.obstacles, duration=8.0)
    assert_equal_runs(a, b)
    assert {0, 1, 2} <= set(np.unique(a.mode))         # every mode was exercised


def test_crowded_swarm_with_wheels_compiled_equals_interpreted():
    """Robots crowded onto obstacles (AVOID, ROTATE, corner takeovers, collisions counted),
    through the wheel plant with a drive latency, in a rotating formation."""
    rng = np.random.default_rng(3)
    n = 40
    poses = np.column_stack([rng.uniform(-20, 0, n), rng.uniform(-10, 10, n),
                             rng.uniform(-math.pi, math.pi, n)])
    form = Formation(formation_offsets(FormationKind.CIRCLE, n, 2.5), (15.0, 0.0),
                     (1.0, 0.5), omega=0.2)
    obstacles = Obstacles(rng.uniform([-5, -10], [12, 10], (8, 2)), rng.uniform(0.5, 2.5, 8))
    a, b = both(np.arange(n), poses, form, obstacles,
                robot=RobotParams(wheel_ramp=5.0, drive_latency=0.05),
                duration=4.0, plant=PlantKind.WHEELS)
    assert_equal_runs(a, b)
    assert a.metrics.summary("x", 1.0)["mode_switches"] > 0


def test_imperfect_world_compiled_equals_interpreted():
    """Every imperfection at once: the same random draws and the same run, compiled or not."""
    sc = load_scenario(SCENARIOS / "paper.toml")
    world = WorldParams(seed=5, link_delay=0.2, link_jitter=0.05, link_loss=0.2,
                        loss_burst=3.0, wheel_slip=0.03, encoder_noise=0.002,
                        detection_noise=0.1, detection_dropout=0.1,
                        kill=(Kill(robot=3, at=2.0),))
    a, b = both(sc.ids, sc.poses, sc.formation, sc.obstacles, world=world, duration=6.0,
                plant=PlantKind.WHEELS)
    assert_equal_runs(a, b)
    assert a.metrics.summary("x", 1.0)["max_pose_error"] > 0


def test_approach_compiled_equals_interpreted():
    """The governor's bound along a neighbour's report, on random inputs, bit for bit (a
    ``** 2`` there once rounded differently interpreted, through pow, than compiled)."""
    from agent.discs import approach
    rng = np.random.default_rng(1)
    compiled_approach = compiled.kernels().approach
    for _ in range(20000):
        args = (*rng.uniform(-5, 5, 2), *rng.uniform(-4, 4, 3), float(rng.choice([0.0, 0.3])),
                model(accel=float(rng.choice([1.0, 25.0])), half_base=rng.uniform(0.2, 0.4)))
        assert approach(*args) == compiled_approach(*args), args


def test_compiled_needs_numba(monkeypatch):
    monkeypatch.setattr(compiled, "available", lambda: False)
    sc = load_scenario(SCENARIOS / "paper.toml")
    with pytest.raises(RuntimeError, match="numba is not installed"):
        simulate(sc.ids, sc.poses, sc.formation, sc.obstacles, sc.control, sc.robot,
                 SimOptions(duration=0.1, compiled=True))


def test_the_cache_follows_every_source(tmp_path, monkeypatch):
    """An edited law (not only an edited caller) gets a fresh cache: numba alone would load
    the caller's stale machine code."""
    import types

    monkeypatch.setenv("BOUNDSWARM_NUMBA_CACHE", str(tmp_path))
    files = [tmp_path / "law.py", tmp_path / "step.py"]
    for f in files:
        f.write_text("x = 1\n")
    modules = []
    for f in files:                             # stand-ins for the law's modules
        modules.append(module := types.ModuleType(f.stem))
        module.__file__ = str(f)
    first = compiled.cache_dir(modules, "0.60")
    assert first.parent == tmp_path and compiled.cache_dir(modules, "0.60") == first
    files[0].write_text("x = 2\n")
    assert compiled.cache_dir(modules, "0.60") != first
    assert compiled.cache_dir(modules, "0.61") != compiled.cache_dir(modules, "0.60")
    second = compiled.cache_dir(modules, "0.60")
    options = tmp_path / "compiled.py"          # how they are compiled (inlining)
    options.write_text("INLINED = ()\n")
    monkeypatch.setattr(compiled, "__file__", str(options))
    assert compiled.cache_dir(modules, "0.60") != second


def test_the_governor_s_helpers_are_compiled_into_their_callers():
    """The governor's helpers run per neighbour per robot: they are inlined into their
    callers, the law's own functions are not (docs/performance.md)."""
    k = compiled.kernels()
    assert k._capsule.targetoptions["inline"] == "always"
    assert k._own_share.targetoptions["inline"] == "always"
    assert k.law_step.targetoptions["inline"] == "never"
