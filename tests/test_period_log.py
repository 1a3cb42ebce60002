"""A robot's periods on file (agent.period_log), replayed through the batch simulator's
compiled period (firmware_sim.period_replay): the same commands, bit for bit."""
import math

import numpy as np
import pytest
from fakes import MirrorMotor, SharedSwarm
from helpers import SimClock
from hypothesis import given, settings
from hypothesis import strategies as st

from agent.config import ControlParams, RobotParams
from agent.exchange import Exchange
from agent.formation import Places
from agent.law import LawMemory
from agent.neighbours import Reports
from agent.node import Agent, _workspace
from agent.params import PeriodParams
from agent.period import Detections, Inputs, Memory, Own, robot_period
from agent.period_log import PeriodLog, PeriodRecord, read_periods
from agent.settings import AgentSettings
from agent.trail import OwnPath
from common.payloads import MissionMsg, ObstaclesMsg
from common.vocabulary import AgentMode
from firmware_sim.period_replay import replay

CART = RobotParams(wheel_radius=0.0825, wheel_speed_limit=5.79, wheel_ramp=3.86,
                   drive_latency=0.02, wheel_slip=0.1, turn_up=1.5)


def run_logged(tmp_path, ticks: int = 150) -> list:
    """Four carts crossing each other past an obstacle, their states a few periods old,
    each recording its periods; the paths of the logs."""
    clock = SimClock()
    net = SharedSwarm(clock)
    poses = [(0.0, 0.0, 0.0), (8.0, 0.5, math.pi), (4.0, -4.0, 1.5), (4.0, 4.5, -1.5)]
    ids = np.arange(1, 5)
    net.mission_msg = MissionMsg(1, clock.wall(), clock.wall(), (4.0, 0.0), (0.3, 0.0), 0.0,
                                 ids, np.array([[4.0, 0.0], [-4.0, 0.0], [0.0, 4.0],
                                                [0.0, -4.0]]))
    agents, paths = [], []
    for rid, pose in zip(ids, poses):
        path = tmp_path / f"agent_{rid}.periods"
        s = AgentSettings(robot_id=int(rid), swarm="t", initial_pose=pose, autostart=True,
                          robot=CART, control=ControlParams(), record_periods=str(path))
        agent = Agent(s, MirrorMotor(clock), net.port(int(rid)), clock,
                      periods=PeriodLog(path))
        agent.arm()
        agent.set_mode(AgentMode.FORMATION)
        net.obstacle_msgs[int(rid)] = ObstaclesMsg(int(rid), 1, clock.wall(),
                                                    np.array([[4.0, 1.5]]), np.array([0.7]))
        agents.append(agent)
        paths.append(path)
    for _ in range(ticks):
        for agent in agents:
            agent.tick()
            clock.now += 0.005                   # the robots tick apart
    for agent in agents:
        assert agent.periods is not None
        agent.periods.close()
    assert sum(a.counters.governed for a in agents) > 20       # the governor was busy
    return paths


def test_replayed_periods_give_the_agent_s_commands_bit_for_bit(tmp_path):
    for path in run_logged(tmp_path):
        records = list(read_periods(path))
        assert len(records) > 100
        done = replay(records)
        assert done.periods == len(records) and done.mismatches == []


def test_a_command_the_agent_changed_after_its_period_is_found(tmp_path):
    path = run_logged(tmp_path, 60)[0]
    records = list(read_periods(path))
    bent = records[30]._replace(sent=(records[30].sent[0] * (1 + 1e-15) + 1e-300,
                                      records[30].sent[1]))
    done = replay(records[:30] + [bent] + records[31:])
    assert len(done.mismatches) == 1 and done.mismatches[0].startswith("period 30 ")


def test_a_file_that_is_no_period_log_is_refused_naming_it(tmp_path):
    bad = tmp_path / "notes.txt"
    bad.write_bytes(b"hello")
    with pytest.raises(ValueError, match="notes.txt: not a period log"):
        list(read_periods(bad))


@st.composite
def surroundings(draw):
    """A robot's period in random surroundings: neighbours of every age (fresh, silent,
    from the future, never heard, its own row), in and beyond range, discs of robots that
    turn and brake, obstacles, the formation's places (a partner asked), its path and the
    pairs it avoided."""
    coord = st.floats(-12.0, 12.0)
    n = draw(st.integers(0, 8))
    ids = draw(st.permutations(list(range(1, 10))))[:n]
    ages = [draw(st.sampled_from([0.0, -0.05, 0.02, 0.3, 0.49, 0.51, 3.0, math.inf]))
            for _ in ids]
    reports = Reports(list(ids) + [0], [NOW - a for a in ages] + [NOW - 0.1],
                      [draw(coord) for _ in ids] + [0.0], [draw(coord) for _ in ids] + [0.0],
                      [draw(st.floats(-4.0, 4.0)) for _ in ids] + [0.0],
                      [draw(st.floats(-3.0, 3.0)) for _ in ids] + [0.0],
                      [draw(st.floats(-2.0, 2.0)) for _ in ids] + [0.0],
                      [draw(st.integers(-1, 9)) for _ in ids] + [0],
                      [draw(st.sampled_from([-1, 0, 1, 2])) for _ in ids] + [-1],
                      [draw(st.integers(-1, 9)) for _ in ids] + [-1])
    k = draw(st.integers(0, 3))
    det = Detections([draw(coord) for _ in range(k)], [draw(coord) for _ in range(k)],
                     [draw(st.floats(0.2, 3.0)) for _ in range(k)], k)
    places = Places(np.array([[4.0 * (s % 4), 4.0 * (s // 4)] for s in range(10)]),
                    np.array([draw(coord), draw(coord), 0.5, -0.2, draw(st.sampled_from(
                        [0.0, 0.1]))]))
    x, y, theta = draw(coord), draw(coord), draw(st.floats(-4.0, 4.0))
    times = [NOW - 0.02 * j for j in range(30, -1, -1)]
    path = OwnPath(times, [x - 0.03 * j for j in range(30, -1, -1)], [y] * 31,
                   [0.03 * j for j in range(31)], 0, 31, 31)
    held = [i for i in ids if draw(st.booleans())]
    own = Own(0, x, y, theta, draw(st.sampled_from([0.0, 0.05])),
              draw(st.sampled_from([0.0, 0.01])), 0.0)
    inputs = Inputs(own, NOW, 30.0, draw(st.sampled_from([0.02, 0.031])), reports,
                    list(range(n + 1)), n + 1, det, places, path, held, len(held))
    wheels = st.floats(-5.0, 5.0)
    law = LawMemory(draw(coord), draw(coord), draw(st.booleans()), draw(st.booleans()),
                    draw(st.sampled_from([-1, 0, 1])), draw(coord), draw(coord),
                    draw(st.floats(0.0, 3.0)), draw(wheels), draw(wheels),
                    draw(st.sampled_from([-1, 0, 1])))
    ex = draw(st.sampled_from([Exchange(0), Exchange(0, ids[0] if ids else 3, 1, False, 29.9),
                               Exchange(1, ids[0] if ids else 3, 0, True, 29.0)]))
    control = ControlParams(pair_hysteresis=draw(st.booleans()),
                            governor=draw(st.booleans()))
    robot = draw(st.sampled_from([CART, None]))
    params = PeriodParams.of(control, robot, 8.0, 0.5, 0.1)
    return inputs, Memory(law, ex), params


NOW = 1000.0


@settings(max_examples=300, deadline=None)
@given(surroundings())
def test_the_compiled_period_equals_the_interpreted_one_in_any_surroundings(case):
    """The batch simulator's compiled period (its arrays, its memory records) gives what an
    agent's interpreted one gives, bit for bit, with the pairs it keeps."""
    inputs, memory, params = case
    ws = _workspace(2 * (inputs.n_near + inputs.detections.n) + 1)
    want = robot_period(inputs, memory, params, ws)
    record = PeriodRecord(inputs, memory, params, want, list(ws.held[:want.n_held]),
                          (want.right, want.left))
    done = replay([record])
    assert done.mismatches == []
