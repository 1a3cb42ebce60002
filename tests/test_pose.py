"""Odometry fused with pose fixes (agent.pose) and the agent's use of it, on simulated time."""
import math

import numpy as np
import pytest
from fakes import MirrorMotor, SharedSwarm
from helpers import SimClock, governor_discs

from agent.config import RobotParams
from agent.kinematics import TWO_PI, arc_step, body_velocity
from agent.node import Agent
from agent.pose import PoseFusion, PoseSettings
from agent.settings import AgentSettings, load_settings
from common.payloads import FixMsg, MissionMsg, ObstaclesMsg, StateMsg
from common.schema import ConfigError
from common.vocabulary import AgentMode, StateFlags

T0 = 1.7e9
CART = RobotParams(wheel_radius=0.0825, wheel_base=0.8, wheel_speed_limit=5.79,
                   wheel_ramp=3.86, drive_latency=0.02)


def fix(t, x, y, theta, error=0.005, rid=1):
    return FixMsg(rid, 0, t, x, y, theta, error)


def test_a_late_fix_is_applied_at_its_capture_time_and_odometry_since_reapplied():
    f = PoseFusion(PoseSettings(), wheel_base=0.5)
    for k in range(61):                       # odometry: along x at 1 m/s, every 10 ms
        f.update(T0 + 0.01 * k, (0.01 * k, 0.0, 0.0))
    # captured at 0.5 s (truth 0.1 m to the left), received at 0.6 s: the first fix is taken
    assert f.fix(fix(T0 + 0.5, 0.5, 0.1, 0.0))
    assert f.pose == pytest.approx((0.6, 0.1, 0.0))      # not (0.5, 0.1): latency compensated
    assert f.uncertainty == pytest.approx(0.005 + 0.05 * 0.1)   # + drift since the fix


def test_a_heading_correction_turns_the_path_driven_since_the_fix():
    f = PoseFusion(PoseSettings(), wheel_base=0.5)
    for k in range(11):
        f.update(T0 + 0.1 * k, (0.1 * k, 0.0, 0.0))
    assert f.fix(fix(T0 + 0.5, 0.5, 0.0, 0.3))            # truth heading 0.3 rad at 0.5 s
    # the 0.5 m driven since then, along the corrected heading
    assert f.pose == pytest.approx((0.5 + 0.5 * math.cos(0.3), 0.5 * math.sin(0.3), 0.3))
    f.update(T0 + 1.1, (1.1, 0.0, 0.0))
    assert f.pose == pytest.approx((0.5 + 0.6 * math.cos(0.3), 0.6 * math.sin(0.3), 0.3))


def test_the_gain_weighs_the_estimate_against_the_fix_and_uncertainty_grows_with_driving():
    f = PoseFusion(PoseSettings(drift=0.05), wheel_base=0.5)
    f.update(T0, (0.0, 0.0, 0.0))
    f.fix(fix(T0, 0.0, 0.0, 0.0, error=0.01))
    assert f.uncertainty == pytest.approx(0.01)
    f.update(T0 + 1.0, (1.0, 0.0, 0.0))                    # 1 m driven: + 5 cm
    assert f.uncertainty == pytest.approx(0.06)
    f.fix(fix(T0 + 1.0, 1.0, 0.06, 0.0, error=0.01))
    g = 0.06 ** 2 / (0.06 ** 2 + 0.01 ** 2)
    assert f.pose[1] == pytest.approx(g * 0.06)
    assert f.uncertainty == pytest.approx(math.sqrt(0.06 ** 2 * 0.01 ** 2 / (0.06 ** 2 + 1e-4)))
    f.update(T0 + 1.5, (1.0, 0.0, 1.0))                    # turning in place drives too
    assert f.uncertainty > 0.01 + 0.05 * 0.25 * 0.9


def test_repeated_and_too_old_fixes_are_not_applied():
    f = PoseFusion(PoseSettings(history=0.2), wheel_base=0.5)
    for k in range(51):
        f.update(T0 + 0.01 * k, (0.01 * k, 0.0, 0.0))
    assert f.fix(fix(T0 + 0.45, 0.45, 0.0, 0.0))
    assert not f.fix(fix(T0 + 0.45, 0.45, 0.0, 0.0))       # the same fix again
    assert not f.fix(fix(T0 + 0.40, 0.40, 0.0, 0.0))       # older than the one applied
    g = PoseFusion(PoseSettings(history=0.2), wheel_base=0.5)
    for k in range(51):
        g.update(T0 + 0.01 * k, (0.01 * k, 0.0, 0.0))
    assert not g.fix(fix(T0 + 0.1, 0.1, 0.0, 0.0))          # before the odometry kept
    assert g.dropped_late == 1 and g.applied == 0 and math.isinf(g.uncertainty)
    # a source whose clock runs ahead: its fixes would never age, so they are not taken
    assert not g.fix(fix(T0 + 0.5 + 0.6, 0.5, 0.0, 0.0))
    assert g.dropped_future == 1 and g.applied == 0
    assert g.fix(fix(T0 + 0.5 + 0.4, 0.5, 0.0, 0.0))         # ahead, within the timeout


# --- the agent on a slipping robot with a simulated motion-capture system -----------------
class SlipWorld:
    """The truth of a MirrorMotor robot whose wheels slip: the ground moves by ``grip`` of
    each wheel's (right, left) turn."""

    def __init__(self, motor, robot, pose, grip):
        self.motor, self.robot, self.pose, self.grip = motor, robot, tuple(pose), grip

    def step(self, dt):
        r = self.robot
        right, left = (TWO_PI * self.motor.vel * self.grip) if self.motor.armed else (0.0, 0.0)
        v, u = body_velocity(right, left, r.wheel_radius, r.wheel_base)
        x, y, theta = self.pose
        self.pose = arc_step(x, y, theta, v * dt, u * dt)


class FixFeed:
    """A simulated motion-capture system (common.ports.FixPort): the truth captured every
    ``1 / rate`` s, delivered ``latency`` s later; none while ``stopped``."""

    def __init__(self, clock, world, rate=100.0, latency=0.03, error=0.005):
        self.clock, self.world, self.latency, self.error = clock, world, latency, error
        self.period, self.next, self.queue, self.latest = 1.0 / rate, 0.0, [], None
        self.stopped = False

    def capture(self):
        now = self.clock.wall()
        if now + 1e-9 >= self.next and not self.stopped:
            self.next = now + self.period
            x, y, theta = self.world.pose
            self.queue.append(FixMsg(1, 0, now, x, y, theta, self.error))
        while self.queue and self.queue[0].stamp + self.latency <= now + 1e-9:
            self.latest = self.queue.pop(0)

    def fix(self):
        return self.latest


def slipping_agent(pose_settings, place=(8.0, 2.0), grip=(0.97, 1.0)):
    clock = SimClock()
    net = SharedSwarm(clock)
    net.mission_msg = MissionMsg(1, clock.wall(), clock.wall(), place, (0.0, 0.0), 0.0,
                                 np.array([1]), np.zeros((1, 2)))
    s = AgentSettings(robot_id=1, swarm="t", initial_pose=(0.0, 0.0, 0.0), robot=CART,
                      pose=pose_settings)
    motor = MirrorMotor(clock)
    world = SlipWorld(motor, s.robot, s.initial_pose, np.array(grip))
    feed = FixFeed(clock, world)
    agent = Agent(s, motor, net.port(1), clock, feed if pose_settings else None)
    return clock, net, agent, world, feed


def drive(clock, agent, world, feed, seconds, errors=None, every=None):
    for k in range(int(round(seconds / 0.02))):
        if every:
            every(k)
        agent.tick()
        if errors is not None:                # where it believes it is, and is, now
            errors.append(math.hypot(agent.pose[0] - world.pose[0],
                                     agent.pose[1] - world.pose[1]))
        for _ in range(2):                    # the world and the capture at 100 Hz
            clock.now += 0.01
            world.step(0.01)
            feed.capture()


def test_fixes_keep_a_slipping_robot_on_its_place_and_odometry_alone_drifts():
    clock, _, agent, world, feed = slipping_agent(PoseSettings())
    drive(clock, agent, world, feed, 0.1)                       # fixes arrive
    assert agent.arm() is None and agent.set_mode(AgentMode.FORMATION) is None
    errors: list[float] = []
    drive(clock, agent, world, feed, 10.0, errors)
    assert max(errors) < 0.05
    assert math.hypot(world.pose[0] - 8.0, world.pose[1] - 2.0) < 0.1
    assert agent.fusion is not None and agent.fusion.applied >= 500   # the newest, each period

    clock, _, alone, world, feed = slipping_agent(None)
    alone.arm()
    alone.set_mode(AgentMode.FORMATION)
    drive(clock, alone, world, feed, 10.0)
    assert math.hypot(alone.pose[0] - world.pose[0], alone.pose[1] - world.pose[1]) > 0.15


def test_a_fix_hands_the_period_the_jump_of_the_estimate():
    """A fix that moves the estimate is handed to the next period as a jump, which moves
    the law's remembered error by as much (agent.period.Own, agent.law.moved_estimate):
    the error's finite difference sees motion only, not the correction (which, divided by
    a period, would be a heading rate)."""
    clock, _, agent, world, feed = slipping_agent(PoseSettings())
    drive(clock, agent, world, feed, 0.1)
    agent.arm()
    agent.set_mode(AgentMode.FORMATION)
    drive(clock, agent, world, feed, 2.0)
    before = agent.fusion.update(clock.wall(), agent.odometry.pose)
    assert agent._jump == (0.0, 0.0)                  # handed to the last period
    x, y, theta = world.pose
    feed.latest = FixMsg(1, 0, clock.wall(), x + 0.3, y - 0.2, theta, 0.005)
    after = agent._estimate(clock.wall())
    assert math.hypot(after[0] - before[0], after[1] - before[1]) > 0.1
    assert agent._jump == pytest.approx((after[0] - before[0], after[1] - before[1]))
    assert agent._estimate(clock.wall()) == after and agent._jump == pytest.approx(
        (after[0] - before[0], after[1] - before[1]))   # the same fix again: no second jump


def test_no_arming_without_a_fix_and_a_stale_fix_brakes_to_a_sticky_hold():
    clock, net, agent, world, feed = slipping_agent(PoseSettings(fix_timeout=0.25))
    feed.stopped = True
    drive(clock, agent, world, feed, 0.1)
    assert agent.arm() == "arming refused: no pose fix yet"
    assert agent.mode is AgentMode.DISARMED and not agent.motor.armed
    feed.stopped = False
    drive(clock, agent, world, feed, 0.1)
    assert agent.arm() is None and agent.set_mode(AgentMode.FORMATION) is None
    drive(clock, agent, world, feed, 2.0)
    assert agent.command[0] > 0.5                               # on its way
    feed.stopped = True                                         # the fix stops for 1 s
    moving = world.pose
    drive(clock, agent, world, feed, 1.0)
    assert agent.mode is AgentMode.HOLD
    assert agent.failsafe is not None and agent.failsafe.startswith("pose fix 0.2")
    assert "old (limit 0.25 s)" in agent.failsafe
    assert net.states[1].msg.flags & StateFlags.FAILSAFE
    assert agent.motor.vel.tolist() == [0.0, 0.0]               # commanded to stop
    stopped = world.pose
    feed.stopped = False
    drive(clock, agent, world, feed, 0.5)
    assert world.pose == stopped and agent.mode is AgentMode.HOLD   # sticky
    assert math.hypot(stopped[0] - moving[0], stopped[1] - moving[1]) < 1.0
    assert agent.set_mode(AgentMode.FORMATION) is None          # the ground station resumes
    feed.stopped = True
    drive(clock, agent, world, feed, 0.5)
    assert agent.set_mode(AgentMode.FORMATION).startswith("pose fix")


def test_the_position_uncertainty_grows_every_hazard(monkeypatch):
    clock, net, agent, world, feed = slipping_agent(PoseSettings(drift=0.1))
    drive(clock, agent, world, feed, 0.1)
    net.obstacle_msgs[1] = ObstaclesMsg(1, 1, clock.wall(), np.array([[3.0, 0.0]]),
                                        np.array([0.5]))
    net.port(2).publish(StateMsg(2, 1, clock.wall(), 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 3.0, 0,
                                 StateFlags.ARMED))

    def radii():
        folded, _ = governor_discs(monkeypatch, agent, net.obstacle_msgs[1])
        east = [h[0] + agent.pose[0] for h in folded]
        assert east == pytest.approx([3.0, 0.0])                # the obstacle, the neighbour
        return np.array([folded[0][2], folded[1][3]])

    before, u0 = radii(), agent.fusion.uncertainty
    assert 0.0 < u0 <= 0.005
    agent.fusion._bound = 0.4                                   # as after a long way blind
    assert radii() == pytest.approx(before - u0 + 0.4)


def test_the_pose_table_is_read_and_checked_naming_file_and_key(tmp_path):
    good = tmp_path / "agent.toml"
    good.write_text('robot_id = 1\nswarm = "s"\ninitial_pose = [0, 0, 0]\n'
                    '[pose]\nfix_timeout = 0.5\n')
    assert load_settings(good).pose == PoseSettings(fix_timeout=0.5)
    bad = tmp_path / "bad.toml"
    bad.write_text('robot_id = 1\nswarm = "s"\ninitial_pose = [0, 0, 0]\n'
                   '[pose]\nfix_timeout = 0.5\ntimeout = 1\n')
    with pytest.raises(ConfigError, match=r"bad.toml \[pose\]: unknown field\(s\) timeout"):
        load_settings(bad)
    with pytest.raises(ConfigError, match="PoseSettings.drift: must be <= 1"):
        PoseSettings(drift=2.0)
    clock = SimClock()
    with pytest.raises(ValueError, match="port of its fixes"):
        Agent(load_settings(good), MirrorMotor(clock), SharedSwarm(clock).port(1), clock)


def test_a_ground_station_is_told_why_arming_is_refused():
    from agent.process import AgentVehicle
    clock, net, agent, world, feed = slipping_agent(PoseSettings())
    feed.stopped = True
    drive(clock, agent, world, feed, 0.1)
    assert AgentVehicle(agent).arm() == "arming refused: no pose fix yet"
    feed.stopped = False
    drive(clock, agent, world, feed, 0.1)
    assert AgentVehicle(agent).arm() is None and AgentVehicle(agent).state().mode is \
        AgentMode.HOLD
