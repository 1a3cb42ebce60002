"""The agent's read -> update -> write over in-memory ports, on simulated time."""
import math

import numpy as np
import pytest
from fakes import MirrorMotor, SharedSwarm, SwarmView
from helpers import SimClock, governor_discs, model, sensed

from agent.config import ControlParams, RobotParams
from agent.discs import neighbour_hazard
from agent.loop import FixedRateLoop
from agent.node import Agent
from agent.settings import AgentSettings
from agent.trail import SPLITS, Splits, own_motion
from common.payloads import MissionMsg, ObstaclesMsg
from common.vocabulary import AgentMode, Mode, StateFlags


def make_swarm(poses, offsets, center0=(0.0, 0.0), velocity=(0.0, 0.0), epoch_in=0.0,
               robot=None, control=None):
    clock = SimClock()
    net = SharedSwarm(clock)
    ids = np.arange(1, len(poses) + 1)
    net.mission_msg = MissionMsg(1, clock.wall(), clock.wall() + epoch_in, center0, velocity,
                                 0.0, ids, np.asarray(offsets, float))
    agents = []
    for rid, pose in zip(ids, poses):
        s = AgentSettings(robot_id=int(rid), swarm="t", initial_pose=tuple(pose),
                          autostart=True, **({"robot": robot} if robot else {}),
                          **({"control": control} if control else {}))
        agents.append(Agent(s, MirrorMotor(clock), net.port(int(rid)), clock))
    return clock, net, agents


def run(clock, agents, seconds):
    loop = FixedRateLoop(ControlParams().period, clock)

    def tick(k: int, d: float) -> None:
        for a in agents:
            a.tick(k, d)

    loop.run(tick, max_ticks=int(seconds / loop.period))
    return loop


def test_a_single_agent_reaches_its_place():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(6.0, 3.0))
    agent.arm()
    assert agent.set_mode(AgentMode.FORMATION) is None
    run(clock, [agent], 6.0)
    assert np.hypot(*(np.subtract(agent.odometry.pose[:2], [6.0, 3.0]))) < 0.05
    last = agent.swarm.published[-1]
    assert last.flags == StateFlags.ARMED and last.x_d == pytest.approx(6.0)


def test_agents_swap_through_each_other_without_collision():
    clock, net, agents = make_swarm([(-6.0, 0.0, 0.0), (6.0, 0.3, np.pi)],
                                    [(6.0, 0.0), (-6.0, 0.0)],
                                    control=ControlParams(exchange=0.0))   # places fixed
    dmin = np.inf
    for a in agents:
        a.arm()
        a.set_mode(AgentMode.FORMATION)
    for _ in range(600):
        for a in agents:
            a.tick()
        clock.now += 0.02
        gap = np.subtract(agents[0].odometry.pose[:2], agents[1].odometry.pose[:2])
        dmin = min(dmin, np.hypot(*gap))
    assert dmin > 1.0
    assert agents[0].odometry.pose[0] > 5.0 and agents[1].odometry.pose[0] < -5.0
    modes = {m.mode for m in agents[0].swarm.published}
    assert Mode.AVOID in modes


def test_agents_exchange_places_over_their_state_messages():
    """Each agent stands at the other's place: they exchange places through the handshake
    in their state messages (agent.exchange) and stay where they are."""
    clock, net, agents = make_swarm([(-4.0, 0.0, 0.0), (4.0, 0.0, np.pi)],
                                    [(4.0, 0.0), (-4.0, 0.0)])
    for a in agents:
        a.arm()
        a.set_mode(AgentMode.FORMATION)
    run(clock, agents, 3.0)
    assert [a.exchange.slot for a in agents] == [1, 0]
    assert [a.counters.place_changes for a in agents] == [1, 1]
    last = [a.swarm.published[-1] for a in agents]
    assert [(m.slot, m.partner, m.other) for m in last] == [(1, -1, -1), (0, -1, -1)]
    assert last[0].x_d == pytest.approx(-4.0) and last[1].x_d == pytest.approx(4.0)
    for a, x in zip(agents, (-4.0, 4.0)):
        assert abs(a.odometry.pose[0] - x) < 0.5


def test_agents_keep_the_pair_hysteresis_by_neighbour_id():
    """Hysteresis per pair: a neighbour that came within b stays avoided out to b +
    hysteresis, remembered by its id; released beyond, it is not avoided again at the same
    distance until it comes within b."""
    import dataclasses
    clock, net, (a, b) = make_swarm([(0.0, 0.0, 0.0), (1.8, 0.0, 0.0)],
                                    [(0.0, 20.0), (1.8, 0.0)])
    a = Agent(dataclasses.replace(a.s, control=ControlParams(pair_hysteresis=True)),
              MirrorMotor(clock), a.swarm, clock)
    a.arm()
    a.set_mode(AgentMode.FORMATION)
    p = a.s.control
    seen = []
    for x in (1.8, p.b + 0.3, p.b + p.hysteresis + 0.2, p.b + 0.3):
        b.odometry.pose = (a.odometry.pose[0] + x, a.odometry.pose[1], 0.0)
        b.tick()
        a.tick()
        clock.now += p.period
        seen.append((a.law_mode, set(a._held)))
    assert seen == [(Mode.AVOID, {2}), (Mode.AVOID, {2}), (Mode.TRACK, set()),
                    (Mode.TRACK, set())]


def test_hold_before_the_epoch_and_disarmed_sends_nothing():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(5.0, 0.0),
                                      epoch_in=1.0)
    agent.tick()
    assert agent.motor.commands == 0 and agent.mode is AgentMode.DISARMED
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    run(clock, [agent], 0.9)
    assert agent.motor.commands > 0 and np.allclose(agent.motor.pos, 0.0)   # watchdog fed
    run(clock, [agent], 0.5)
    assert agent.motor.pos.sum() > 0                                          # moving now


def test_lost_feedback_is_a_sticky_failsafe_hold():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(20.0, 0.0))
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    run(clock, [agent], 0.5)
    agent.motor.silent = True
    agent.tick()
    assert agent.mode is AgentMode.HOLD and agent.failsafe == "driver feedback lost"
    assert agent.motor.vel.tolist() == [0.0, 0.0]
    assert agent.swarm.published[-1].flags & StateFlags.FAILSAFE
    agent.motor.silent = False
    run(clock, [agent], 0.2)
    assert agent.mode is AgentMode.HOLD                   # stays until asked again
    agent.set_mode(AgentMode.FORMATION)
    run(clock, [agent], 0.2)
    assert agent.failsafe is None and agent.motor.vel.sum() > 0


def test_driver_error_triggers_failsafe_with_its_name():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(20.0, 0.0))
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    agent.motor.errors = ("WATCHDOG_TIMER_EXPIRED",)
    agent.tick()
    assert agent.failsafe == "driver error: WATCHDOG_TIMER_EXPIRED"
    assert agent.counters.failsafes == 1


def test_stale_neighbour_is_avoided_as_a_static_obstacle():
    """On a cart (3 m/s, 2 m/s^2): the governor keeps it out of the silent robot's disc
    (where that could have driven before it must have stopped: 2.0 m), and the law goes
    round it as an obstacle of that disc less a (agent.governor.silent_radius)."""
    cart = RobotParams(wheel_radius=0.0825, wheel_base=0.8, wheel_speed_limit=5.79,
                       wheel_ramp=3.86, drive_latency=0.02)
    clock, net, agents = make_swarm([(0.0, 0.0, 0.0), (4.0, 0.0, 0.0)],
                                    [(0.0, 0.0), (0.0, 0.0)], center0=(12.0, 0.0), robot=cart)
    a, b = agents
    b.tick()                                   # b publishes once, then goes silent
    clock.now += 1.0                           # older than the 0.5 s staleness
    a.arm()
    a.set_mode(AgentMode.FORMATION)
    nbrs, obstacles = sensed(a, a.swarm.obstacles())
    disc = neighbour_hazard(0.0, 0.0, 1.0, 0.0, model(
        accel=cart.a_max, top_speed=cart.v_wheel_max, staleness=0.5,
        stop_time=0.1 + cart.drive_latency, speed_up=cart.a_up,
        lag=0.02 + cart.drive_latency))[0]
    assert disc == pytest.approx(1.97, abs=0.01)
    assert nbrs == [] and obstacles == [(4.0, 0.0, pytest.approx(disc - 1.0))]
    dmin = np.inf
    for _ in range(400):
        a.tick()
        clock.now += 0.02
        dmin = min(dmin, np.hypot(*(np.subtract(a.odometry.pose[:2], [4.0, 0.0]))))
    assert dmin > disc                         # went around it, outside the disc
    assert a.odometry.pose[0] > 8.0


def test_obstacles_from_the_swarm_port_are_used():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(16.0, 0.0))
    net.obstacle_msgs[1] = ObstaclesMsg(1, 1, clock.wall(), np.array([[8.0, 0.0]]),
                                        np.array([2.0]))
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    clear = np.inf
    for _ in range(500):
        agent.tick()
        clock.now += 0.02
        clear = min(clear, np.hypot(*(np.subtract(agent.odometry.pose[:2], [8.0, 0.0]))) - 2.0)
    assert clear > 1.0 and agent.odometry.pose[0] > 14.0
    assert Mode.ROTATE in {m.mode for m in agent.swarm.published}


def test_mode_requests_are_validated():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)])
    assert agent.set_mode(AgentMode.FORMATION) == "not armed"
    agent.arm()
    assert agent.set_mode(AgentMode.DISARMED) == "use disarm to disarm"
    agent.shutdown()
    assert agent.mode is AgentMode.DISARMED and not agent.motor.armed


def test_arming_waits_for_drivers_that_boot_late_and_repeats_the_request():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(20.0, 0.0))
    agent.motor.silent = True
    agent.arm()
    agent.motor.armed = False                  # the first request was lost
    agent.set_mode(AgentMode.FORMATION)
    run(clock, [agent], 2.0)
    assert agent.failsafe is None and agent.motor.pos.sum() == 0
    agent.motor.silent = False                 # the drivers come up
    run(clock, [agent], 1.0)
    assert agent.failsafe is None and agent.motor.armed and agent.motor.pos.sum() > 0


def test_drivers_that_never_arm_are_a_failsafe():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)], center0=(20.0, 0.0))
    agent.motor.silent = True
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    run(clock, [agent], 5.5)
    assert agent.failsafe == "drivers not armed within 5 s (no feedback)"


def test_every_period_reads_the_same_ports_whatever_the_mode():
    """Neighbours and detections are read every tick, disarmed and before the epoch too:
    samples never pile up until the mission starts (when every agent would drain its
    backlog in the same period)."""
    clock, net, (a, b) = make_swarm([(0.0, 0.0, 0.0), (4.0, 0.0, 0.0)],
                                    [(0.0, 0.0), (0.0, 4.0)], epoch_in=1.0)
    reads = []
    def counting(name):
        f = getattr(a.swarm, name)

        def counted():
            reads.append(name)
            return f()
        return counted

    for name in ("neighbours", "obstacles", "mission"):
        setattr(a.swarm, name, counting(name))
    a.tick()                                   # disarmed
    a.arm()
    a.set_mode(AgentMode.FORMATION)
    clock.now += 0.02
    a.tick()                                   # formation, before the epoch
    clock.now += 1.0
    b.tick()
    a.tick()                                   # formation, mission running
    assert reads == ["mission", "neighbours", "obstacles"] * 3


def test_runtime_parameters_change_through_set_param_only_when_valid():
    clock, net, (agent,) = make_swarm([(0.0, 0.0, 0.0)], [(0.0, 0.0)])
    before = agent.s
    assert agent.param("BS_K_THETA") == 3.0
    assert agent.set_param("BS_K_THETA", 2.5) is None
    assert agent.s.control.K_theta == agent.param("BS_K_THETA") == 2.5
    assert agent._params.law.K_theta == 2.5                 # the law runs the new gain
    assert agent.s.robot == before.robot and agent.s.timeouts == before.timeouts
    settled = agent.s
    for name, value, why in [("BS_K", -1.0, "BS_K = -1 refused: ControlParams.K: must be > 0"),
                             ("BS_B", 10.0, "need 0 < a < b < c"),
                             ("BS_PERIOD", 0.01, "BS_PERIOD is read-only at runtime"),
                             ("BS_NOPE", 1.0, "no parameter BS_NOPE")]:
        reason = agent.set_param(name, value)
        assert reason is not None and why in reason
        assert agent.s is settled
    # the sensing range was fixed at start (2 c), a new c does not move it
    assert agent.set_param("BS_C", 4.5) is None and agent.s.sensing_range == 8.0


def test_a_cart_brakes_for_a_dead_robot_through_its_governor():
    """A cart (3 m/s, 2 m/s^2) drives at a robot whose agent died where it stood (its state
    goes stale): the governor brakes it, and it never comes within a of the dead robot."""
    import dataclasses

    from agent.config import RobotParams
    clock, net, (agent, dead) = make_swarm([(0.0, 0.0, 0.0), (9.0, 0.0, np.pi)],
                                           [(30.0, 0.0), (9.0, 0.0)])
    cart = RobotParams(wheel_radius=0.0825, wheel_speed_limit=5.79, wheel_ramp=3.86,
                       drive_latency=0.02)
    view: SwarmView = agent.swarm
    agent = Agent(dataclasses.replace(agent.s, robot=cart), MirrorMotor(clock), view, clock)
    dead.tick()                                  # publishes once, then never again
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    closest, flagged = np.inf, False
    for _ in range(400):
        agent.tick()
        flagged = flagged or bool(view.published[-1].flags & StateFlags.GOVERNED)
        clock.now += 0.02
        closest = min(closest, np.hypot(*(np.subtract(agent.odometry.pose[:2], (9.0, 0.0)))))
    assert closest > agent.s.control.a
    assert agent.counters.governed > 0 and flagged
    assert agent.counters.summary()["governor_min_allowed"] < cart.v_wheel_max


def test_a_neighbour_s_shared_disc_counts_this_robot_s_path_since_its_stamp(monkeypatch):
    """A robot reported still 0.3 s ago (older than a period, within the staleness limit),
    straight ahead of this agent: its shared disc is a, then what it can have travelled by
    each split of those 0.3 s and the path this agent drove toward it since the split
    began, read off its own odometry, the largest of the pairs (the first holds the whole
    path)."""
    cart = RobotParams(wheel_radius=0.0825, wheel_speed_limit=5.79, wheel_ramp=3.86,
                       drive_latency=0.02)
    clock, net, (agent, other) = make_swarm([(0.0, 0.0, 0.0), (8.0, 0.0, 0.0)],
                                            [(30.0, 0.0), (8.0, 0.0)], robot=cart)
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    for _ in range(50):                          # 1 s: up to speed along x
        agent.tick()
        other.tick()
        clock.now += 0.02
    stamp, x0 = clock.wall(), agent.odometry.pose[0]
    other.tick()                                 # its last report
    for _ in range(15):
        clock.now += 0.02
        agent.tick()
    age, driven = clock.wall() - stamp, agent.odometry.pose[0] - x0
    assert driven > 0.3 and age == pytest.approx(0.3)
    folded, _ = governor_discs(monkeypatch, agent)
    # reported still: it can only have sped up, its wheels a ramp off the report for the
    # lag (a period and the drive latency, A17)
    lag = agent.s.control.period + cart.drive_latency

    def travel(t: float) -> float:
        return 0.5 * cart.a_max * t ** 2 + cart.a_max * lag ** 2

    moved = Splits(*([0.0] * SPLITS for _ in Splits._fields))
    own_motion(agent.trail.path(), stamp, age, [-1] * (2 * SPLITS), moved)
    paths = moved.walked
    pairs = [travel(age * (k + 1) / SPLITS) + paths[k] for k in range(SPLITS)]
    assert pairs[0] == pytest.approx(travel(age / SPLITS) + driven, rel=1e-6)
    assert [h[2] for h in folded] == [-math.inf]
    assert [h[3] for h in folded] == [pytest.approx(agent.s.control.a + max(pairs), rel=1e-6)]


def test_the_law_passes_each_neighbour_s_governor_disc(monkeypatch):
    """The period hands the law each fresh neighbour's disc width beyond a (A13): the half
    radius of its claim, which the governor holds it out of unless it is behind the
    neighbour (then the stop strip's, smaller: A10); none with the governor off."""
    import agent.period as period
    cart = RobotParams(wheel_radius=0.0825, wheel_speed_limit=5.79, wheel_ramp=3.86,
                       drive_latency=0.02)
    seen: list[list[float]] = []        # the growth the law was handed, each period
    discs: list[list] = []              # the discs computed before it
    pending: list = []
    law, radii = period.law_step, period.neighbour_radii

    def spy_law(*args):
        around = args[4]
        seen.append(list(around.nbr_grow[:around.n_nbr]))
        discs.append(list(pending))
        pending.clear()
        return law(*args)

    def spy_radii(*args):
        disc = radii(*args)
        pending.append(disc)
        return disc

    monkeypatch.setattr(period, "law_step", spy_law)
    monkeypatch.setattr(period, "neighbour_radii", spy_radii)
    for governor in (True, False):
        seen.clear()
        discs.clear()
        clock, net, (agent, other) = make_swarm(
            [(0.0, 0.0, 0.0), (6.0, 0.0, 0.0)], [(30.0, 0.0), (36.0, 0.0)], robot=cart,
            control=ControlParams(governor=governor))
        agent.arm()
        agent.set_mode(AgentMode.FORMATION)
        other.arm()
        other.set_mode(AgentMode.FORMATION)
        for _ in range(40):
            agent.tick()
            other.tick()
            clock.now += 0.02
        mine = seen[0::2], discs[0::2]          # the agent's periods (the other's between)
        assert mine[0] and all(len(g) == 1 for g in mine[0][1:])
        if governor:
            a = agent.s.control.a
            computed = [(g[0], d[0]) for g, d in zip(*mine) if d]
            assert len(computed) > len(mine[0]) // 2
            assert [g for g, _ in computed] == pytest.approx([d.claim - a for _, d in computed])
            assert max(g for g, _ in computed) > 0.0
            # behind the other robot as it drives off: the strip holds it less
            assert any(d.half < d.claim - 1e-6 for _, d in computed)
            assert all(d.half <= d.claim + 1e-9 for _, d in computed)
        else:
            assert all(not d for d in discs) and all(g == [0.0] for g in seen[1:])


def test_neighbour_age_is_split_into_stages_and_the_tail_names_the_slow_one():
    from agent.node import AgentCounters, _stages
    from common.payloads import Received, StateMsg
    msg = StateMsg(2, 1, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, StateFlags(0))
    assert _stages(Received(msg, 10.03, 10.01), 10.05) == pytest.approx((0.01, 0.02, 0.02))
    c = AgentCounters()
    for k in range(400):
        stages = _stages(Received(msg, 10.006 + (0.3 if k % 50 == 0 else 0.0), 10.001), 10.0)
        stages = (stages[0], stages[1], 0.002)
        c.neighbour_age.append(sum(stages))
        c.age_stages.append(stages)
    s = c.summary()["neighbour_age_stages_ms"]
    # 8 of 400 uses waited 300 ms more between router and agent: they are the oldest 1 %
    assert s["router_to_agent"]["tail"] == pytest.approx(305.0)
    assert s["publish_to_router"]["tail"] == pytest.approx(1.0)
    assert s["in_agent"]["p50"] == pytest.approx(2.0)
    # without router timestamps (another transport, a fake) the stages are unknown
    bare = AgentCounters()
    bare.neighbour_age.append(0.01)
    bare.age_stages.append(_stages(Received(msg, 10.0), 10.01))
    assert bare.summary()["neighbour_age_stages_ms"] is None
