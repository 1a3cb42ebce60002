import pytest

from agent.config import (ConfigError, ControlParams, RobotParams, braking_margin,
                          check_braking_margin, describe_fields, from_table)


def test_paper_defaults():
    p = ControlParams()
    assert (p.K, p.K_theta, p.D_max, p.K_ij, p.a, p.b, p.c) == (4, 3, 3, 3, 1, 2, 4)
    assert p.period_bound == pytest.approx(1 / 24)
    assert p.v_max == 12.0


def test_period_breaking_the_bound_is_refused_with_the_numbers():
    with pytest.raises(ConfigError) as exc:
        ControlParams(period=0.05)
    msg = str(exc.value)
    assert "period 0.05" in msg and "0.0417" in msg and "(b - a)/(2 K D_max)" in msg


def test_lower_gains_allow_a_longer_period():
    assert ControlParams(period=0.1, K=1.0, D_max=2.0).period == 0.1


@pytest.mark.parametrize("kw, field", [({"a": 2.5}, "a < b < c"), ({"K": -1.0}, "K"),
                                       ({"period": 0.0}, "period"),
                                       ({"hysteresis": float("nan")}, "hysteresis")])
def test_bad_values_name_the_field(kw, field):
    with pytest.raises(ConfigError, match=field):
        ControlParams(**kw)


def test_from_table_refuses_unknown_and_non_numbers():
    with pytest.raises(ConfigError, match=r"x.toml \[control\]: unknown field\(s\) Kp"):
        from_table(ControlParams, {"Kp": 1.0}, "x.toml [control]")
    with pytest.raises(ConfigError, match="'K' must be a number"):
        from_table(ControlParams, {"K": "4"}, "x.toml [control]")
    with pytest.raises(ConfigError, match=r"x.toml \[robot\]: RobotParams.wheel_radius"):
        from_table(RobotParams, {"wheel_radius": 0}, "x.toml [robot]")
    assert from_table(ControlParams, {"K": 2}, "t").K == 2.0


def test_braking_margin_matches_design():
    fast = braking_margin(ControlParams(), RobotParams())
    assert fast.ok and fast.v_max == 12.0
    assert fast.reaction == pytest.approx(0.24)
    slow_ramp = braking_margin(ControlParams(), RobotParams(wheel_ramp=200.0))
    assert not slow_ramp.ok                          # DESIGN: 200 rev/s^2 already breaks it
    with pytest.raises(ConfigError, match="braking margin"):
        check_braking_margin(ControlParams(), RobotParams(wheel_ramp=200.0), strict=True)
    # stale neighbour data eats the margin too
    assert not braking_margin(ControlParams(), RobotParams(), data_age=0.05).ok


def test_braking_margin_warns_when_not_strict(caplog):
    check_braking_margin(ControlParams(), RobotParams(wheel_ramp=200.0))
    assert "EXCEEDS" in caplog.text


def test_every_field_is_documented_with_a_unit():
    for name, default, unit, doc in describe_fields(ControlParams) + describe_fields(RobotParams):
        assert unit and doc and isinstance(default, float), name
