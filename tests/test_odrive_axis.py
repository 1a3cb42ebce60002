"""The emulated firmware of one axis, on simulated time, without any bus."""
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_sim.odrive_axis import AxisConfig, OdriveAxis
from transport.can_codec import AxisError, AxisState, ControlMode, InputMode, ProcedureResult

DT = 0.001


def run(axis: OdriveAxis, seconds: float, vel: float | None = None, feed_every: float = 0.02):
    """Step ``axis`` for ``seconds``; with ``vel``, command it every ``feed_every`` s."""
    every = round(feed_every / DT)
    for k in range(round(seconds / DT)):
        if vel is not None and k % every == 0:
            axis.set_input_vel(vel)
            axis.feed_watchdog()
        axis.step(DT)


def armed(config: AxisConfig | None = None) -> OdriveAxis:
    axis = OdriveAxis(config)
    axis.request_state(AxisState.CLOSED_LOOP_CONTROL)
    assert axis.status().state is AxisState.CLOSED_LOOP_CONTROL
    return axis


@pytest.mark.parametrize("field, value", [
    ("vel_limit_rev_s", 0.0), ("vel_ramp_rate_rev_s2", -1.0), ("watchdog_timeout_s", math.nan),
    ("coast_time_constant_s", 0.0), ("current_limit_a", math.inf), ("idle_current_a", -0.1),
])
def test_config_errors_name_the_field(field, value):
    with pytest.raises(ValueError, match=f"^{field}:"):
        AxisConfig(**{field: value})


def test_boots_idle_and_does_not_move_until_closed_loop():
    axis = OdriveAxis()
    run(axis, 0.2, vel=3.0)
    s = axis.status()
    assert s.state is AxisState.IDLE and s.vel_rev_s == 0.0 and s.pos_rev == 0.0
    assert s.bus_current_a == 0.0 and s.input_vel_rev_s == 3.0     # kept, not acted on


def test_ramp_reaches_the_set_point_in_velocity_over_rate():
    axis = armed(AxisConfig(vel_ramp_rate_rev_s2=100.0))
    axis.set_input_vel(5.0)
    run(axis, 0.049)                                  # 5 rev/s at 100 rev/s^2: 50 ms
    assert axis.status().vel_rev_s == pytest.approx(4.9)
    run(axis, 0.002)
    s = axis.status()
    assert s.vel_rev_s == 5.0 and s.vel_setpoint_rev_s == 5.0
    assert s.pos_rev == pytest.approx(0.5 * 5.0 * 0.05 + 5.0 * 0.001)   # exact ramp integral


def test_passthrough_follows_at_once():
    axis = armed()
    axis.set_controller_mode(ControlMode.VELOCITY_CONTROL, InputMode.PASSTHROUGH)
    axis.set_input_vel(-4.0)
    axis.step(DT)
    assert axis.status().vel_rev_s == -4.0


def test_modes_that_are_not_emulated_brake_to_zero():
    axis = armed()
    run(axis, 0.05, vel=4.0)
    axis.set_controller_mode(ControlMode.POSITION_CONTROL, InputMode.TRAP_TRAJ)
    run(axis, 0.05, vel=4.0)
    assert axis.status().vel_rev_s == 0.0 and axis.status().state is AxisState.CLOSED_LOOP_CONTROL


def test_set_point_is_clamped_to_the_velocity_limit_and_limits_are_settable():
    axis = armed()
    run(axis, 0.05, vel=25.0)
    assert axis.status().vel_rev_s == 10.0
    axis.set_limits(4.0, 5.0)
    axis.step(DT)
    s = axis.status()
    assert (s.vel_limit_rev_s, s.current_limit_a, s.vel_rev_s) == (4.0, 5.0, 4.0)
    axis.set_limits(math.nan, -1.0)                   # ignored
    assert axis.status().vel_limit_rev_s == 4.0 and axis.status().current_limit_a == 5.0


def test_watchdog_trips_after_its_timeout_and_the_wheel_coasts_down():
    axis = armed()
    run(axis, 0.1, vel=2.0)
    axis.feed_watchdog()
    run(axis, 0.1)                                   # exactly the timeout: not yet
    assert axis.status().state is AxisState.CLOSED_LOOP_CONTROL
    axis.step(DT)
    s = axis.status()
    assert s.state is AxisState.IDLE and s.watchdog_trips == 1
    assert s.disarm_reason == AxisError.WATCHDOG_TIMER_EXPIRED
    assert s.axis_error == AxisError.WATCHDOG_TIMER_EXPIRED
    assert s.procedure_result is ProcedureResult.DISARMED
    v0, pos0 = s.vel_rev_s, s.pos_rev
    run(axis, 0.3)                                    # one time constant
    s = axis.status()
    assert s.vel_rev_s == pytest.approx(v0 * math.exp(-1.0))
    assert s.pos_rev - pos0 == pytest.approx(v0 * 0.3 * (1 - math.exp(-1.0)))
    run(axis, 10.0)
    assert axis.status().vel_rev_s == 0.0


def test_watchdog_zero_disables_it():
    axis = armed(AxisConfig(watchdog_timeout_s=0.0))
    run(axis, 1.0)
    assert axis.status().state is AxisState.CLOSED_LOOP_CONTROL


def test_closed_loop_refused_while_an_error_is_set_until_cleared():
    axis = armed()
    axis.estop()
    s = axis.status()
    assert s.state is AxisState.IDLE and s.axis_error == AxisError.ESTOP_REQUESTED
    axis.request_state(AxisState.CLOSED_LOOP_CONTROL)
    assert axis.status().state is AxisState.IDLE
    assert axis.status().procedure_result is ProcedureResult.DISARMED
    axis.clear_errors()
    assert axis.status().axis_error == AxisError.NONE
    axis.request_state(AxisState.CLOSED_LOOP_CONTROL)
    assert axis.status().state is AxisState.CLOSED_LOOP_CONTROL
    assert axis.status().procedure_result is ProcedureResult.BUSY


def test_injected_error_is_active_and_disarms():
    axis = armed()
    axis.raise_error(AxisError.DRV_FAULT)
    s = axis.status()
    assert s.state is AxisState.IDLE
    assert s.active_errors == AxisError.DRV_FAULT == s.disarm_reason


def test_idle_request_and_states_that_are_not_emulated():
    axis = armed()
    axis.request_state(AxisState.IDLE)
    assert axis.status().state is AxisState.IDLE
    assert axis.status().procedure_result is ProcedureResult.SUCCESS
    axis.request_state(AxisState.FULL_CALIBRATION_SEQUENCE)
    assert axis.status().state is AxisState.IDLE
    assert axis.status().procedure_result is ProcedureResult.INVALID_STATE
    axis.request_state(AxisState.UNDEFINED)
    assert axis.status().procedure_result is ProcedureResult.INVALID_STATE


def test_input_velocity_survives_idle_as_in_the_firmware():
    axis = armed()
    axis.set_input_vel(3.0)
    axis.request_state(AxisState.IDLE)
    axis.request_state(AxisState.CLOSED_LOOP_CONTROL)
    run(axis, 0.05)
    assert axis.status().vel_rev_s == 3.0


def test_bus_voltage_and_current_are_plausible():
    axis = armed()
    axis.set_input_vel(10.0)
    axis.step(DT)                                    # accelerating at 1000 rev/s^2
    accelerating = axis.status()
    run(axis, 0.05, vel=10.0)
    cruising = axis.status()
    assert 0 < cruising.bus_current_a < accelerating.bus_current_a <= 20.0
    assert 23.0 < accelerating.bus_voltage_v < cruising.bus_voltage_v < 24.0
    axis.set_limits(10.0, 1.0)
    axis.set_input_vel(-10.0)
    axis.step(DT)
    assert axis.status().bus_current_a == 1.0        # capped at the current limit


def test_time_cannot_go_back():
    with pytest.raises(ValueError, match="^dt:"):
        OdriveAxis().step(-0.001)


commands = st.lists(st.tuples(
    st.sampled_from(["vel", "arm", "idle", "estop", "clear", "limit", "wait"]),
    st.floats(-50, 50, allow_nan=False)), max_size=40)


@settings(max_examples=60, deadline=None)
@given(commands)
def test_closed_loop_speed_respects_limit_and_ramp_whatever_the_host_sends(script):
    axis = OdriveAxis(AxisConfig(vel_ramp_rate_rev_s2=200.0))
    for op, x in script:
        before = axis.status()
        {"vel": lambda: axis.set_input_vel(x), "estop": axis.estop, "clear": axis.clear_errors,
         "arm": lambda: axis.request_state(AxisState.CLOSED_LOOP_CONTROL),
         "idle": lambda: axis.request_state(AxisState.IDLE),
         "limit": lambda: axis.set_limits(abs(x) + 0.5, 10.0),
         "wait": lambda: None}[op]()
        limited = axis.status()
        for _ in range(5):
            axis.step(0.01)
            s = axis.status()
            if s.state is AxisState.CLOSED_LOOP_CONTROL:
                assert abs(s.vel_rev_s) <= s.vel_limit_rev_s + 1e-9
                assert abs(s.vel_rev_s - limited.vel_rev_s) <= 200.0 * 0.01 + 1e-9
            else:
                assert abs(s.vel_rev_s) <= abs(limited.vel_rev_s) + 1e-12   # coasting
            assert math.isfinite(s.pos_rev)
            limited = s
        assert before.watchdog_trips <= axis.status().watchdog_trips
