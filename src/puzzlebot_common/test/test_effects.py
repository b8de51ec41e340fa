import math

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.effects import EFFECTS, ActuatorModel, ActuatorPlant


def run(plant, cmds, t_end, dt=0.001):
    """cmds: list of (t, v, w); returns list of (t, v, w) actual."""
    out, t, pending = [], 0.0, list(cmds)
    while t < t_end - 1e-12:
        while pending and pending[0][0] <= t + 1e-12:
            plant.command(*pending.pop(0))
        out.append((t, *plant.advance(t, dt)))
        t += dt
    return out


def at(trace, t):
    return min(trace, key=lambda r: abs(r[0] - t))


def test_nominal_model_is_identity():
    trace = run(ActuatorPlant(ActuatorModel()), [(0.0, 0.05, 1.0)], 0.1)
    assert trace[0][1:] == (0.05, 1.0)


def test_delay_scale_lag_bias_deadband():
    m = ActuatorModel()
    m.add("input_delay", {"delay_s": 0.1}).add("velocity_scale", {"k_v": 0.8, "k_w": 1.2})
    trace = run(ActuatorPlant(m), [(0.0, 0.05, 1.0)], 0.3)
    assert at(trace, 0.05)[1:] == (0.0, 0.0)
    assert at(trace, 0.2)[1:] == pytest.approx((0.04, 1.2))

    lag = ActuatorModel().add("velocity_lag", {"tau_v_s": 0.2, "tau_w_s": 0.05})
    trace = run(ActuatorPlant(lag), [(0.0, 0.05, 1.0)], 0.5)
    assert at(trace, 0.2)[1] == pytest.approx(0.05 * (1 - math.exp(-1)), rel=0.02)
    assert at(trace, 0.05)[2] == pytest.approx(1 - math.exp(-1), rel=0.05)

    bias = ActuatorModel().add("yaw_rate_bias", {"w_per_v": 2.0, "w0": 0.01})
    assert run(ActuatorPlant(bias), [(0.0, 0.05, 0.0)], 0.01)[0][2] == pytest.approx(0.11)

    dead = ActuatorModel().add("deadband", {"v_min": 0.01, "w_min": 0.2})
    assert run(ActuatorPlant(dead), [(0.0, 0.005, 0.1)], 0.01)[0][1:] == (0.0, 0.0)
    assert run(ActuatorPlant(dead), [(0.0, 0.02, 0.3)], 0.01)[0][1:] == (0.02, 0.3)


def test_heading_offset_wraps():
    plant = ActuatorPlant(ActuatorModel().add("heading_offset", {"offset_rad": 0.2}))
    assert plant.measured_yaw(3.1) == pytest.approx(3.3 - 2 * math.pi)


def test_model_file_round_trip(tmp_path):
    m = ActuatorModel().add("velocity_lag", {"tau_v_s": 0.1, "tau_w_s": 0.2}).add("heading_offset",
                                                                                 {"offset_rad": -0.05})
    path = tmp_path / "model.yaml"
    m.dump(str(path))
    back = ActuatorModel.load(str(path))
    assert back.names() == ["velocity_lag", "heading_offset"]
    assert back.param("tau_w_s") == 0.2 and back.param("k_v") == 1.0


@pytest.mark.parametrize("data, fragment", [
    ({"effects": [{"name": "gremlins", "params": {}}]}, "unknown effect"),
    ({"effects": [{"name": "input_delay", "params": {"delay": 0.1}}]}, "exactly the parameters"),
    ({"effects": [{"name": "input_delay", "params": {"delay_s": -0.1}}]}, ">= 0"),
    ({"effects": [{"name": "velocity_scale", "params": {"k_v": 0, "k_w": 1}}]}, "> 0"),
    ({"effects": {"name": "input_delay"}}, "expected a list"),
    ({"effect": []}, "unknown key"),
])
def test_bad_model_files(data, fragment):
    with pytest.raises(ConfigError) as e:
        ActuatorModel.from_dict(data)
    assert fragment in str(e.value)


def test_every_effect_has_nominal_values():
    from puzzlebot_common.effects import NOMINAL
    assert {p for params in EFFECTS.values() for p in params} == set(NOMINAL)


def test_friction_offset_takes_a_fixed_amount_off_every_command():
    fric = ActuatorModel().add("friction_offset", {"v_c": 0.01, "w_c": 0.2})
    assert run(ActuatorPlant(fric), [(0.0, 0.05, -1.0)], 0.01)[0][1:] == pytest.approx((0.04, -0.8))
    assert run(ActuatorPlant(fric), [(0.0, 0.005, 0.1)], 0.01)[0][1:] == (0.0, 0.0)
    # unlike a deadband, which passes large commands unchanged
    dead = ActuatorModel().add("deadband", {"v_min": 0.01, "w_min": 0.2})
    assert run(ActuatorPlant(dead), [(0.0, 0.05, -1.0)], 0.01)[0][1:] == (0.05, -1.0)


def test_accel_limit_ramps_then_lags():
    """y' = clip((u - y) / tau, -a, a): a ramp at a while the lag would be faster, then the lag."""
    ramp = ActuatorModel().add("accel_limit", {"a_v": 0.5, "a_w": 10.0})
    trace = run(ActuatorPlant(ramp), [(0.0, 0.1, -1.0)], 0.5)
    assert at(trace, 0.1)[1] == pytest.approx(0.05025, abs=1e-9)     # mean of 0.5 t over [0.1, 0.101)
    assert at(trace, 0.3)[1] == pytest.approx(0.1)                   # reached after 0.2 s
    assert at(trace, 0.05)[2] == pytest.approx(-0.505, abs=1e-9)
    both = ActuatorModel().add("accel_limit", {"a_v": 0.5, "a_w": math.inf}).add(
        "velocity_lag", {"tau_v_s": 0.1, "tau_w_s": 0.1})
    plant = ActuatorPlant(both)
    plant.command(0.0, 0.1, 0.0)
    plant.advance(0.0, 0.15)           # saturated until u - y = a tau = 0.05, at t = 0.1 s
    assert plant.v == pytest.approx(0.1 - 0.05 * math.exp(-0.05 / 0.1))
    assert ActuatorModel.from_dict({"effects": [{"name": "accel_limit", "params": {"a_v": 1.0,
                                                                                  "a_w": math.inf}}]})


def test_gain_drift_multiplies_the_actual_velocity_from_t_start():
    m = ActuatorModel().add("gain_drift", {"rate_per_s": -0.01}).add("velocity_scale", {"k_v": 1.2, "k_w": 1.0})
    plant = ActuatorPlant(m, t_start=2.0)
    plant.command(0.0, 0.05, 1.0)
    assert plant.advance(12.0, 0.0) == pytest.approx((0.05 * 1.2 * 0.9, 0.9))
    assert plant.advance(2.0, 2.0) == pytest.approx((0.06 * 0.99, 0.99))     # mean of a linear gain


def test_yaw_rate_bias_acts_on_the_actual_speed_while_driven():
    m = ActuatorModel().add("yaw_rate_bias", {"w_per_v": 2.0, "w0": 0.05}).add(
        "velocity_scale", {"k_v": 0.5, "k_w": 1.0})
    assert run(ActuatorPlant(m), [(0.0, 0.1, 0.0)], 0.01)[0][2] == pytest.approx(2.0 * 0.05 + 0.05)
    assert run(ActuatorPlant(m), [(0.0, 0.0, 0.0)], 0.01)[0][1:] == (0.0, 0.0)     # at rest: no turn
    dead = ActuatorModel().add("yaw_rate_bias", {"w_per_v": 0.0, "w0": 0.05}).add(
        "deadband", {"v_min": 0.01, "w_min": 0.2})
    assert run(ActuatorPlant(dead), [(0.0, 0.005, 0.1)], 0.01)[0][1:] == (0.0, 0.0)   # in the band: not driven


def test_per_robot_entries_replace_the_shared_ones(tmp_path):
    m = ActuatorModel().add("input_delay", {"delay_s": 0.1}).add("velocity_lag", {"tau_v_s": 0.1, "tau_w_s": 0.1})
    m.add_for_robot("pz2", "input_delay", {"delay_s": 0.3}).add_for_robot("pz2", "heading_offset",
                                                                          {"offset_rad": 0.02})
    pz2 = m.for_robot("pz2")
    assert pz2.names() == ["input_delay", "velocity_lag", "heading_offset"]
    assert pz2.param("delay_s") == 0.3 and pz2.param("tau_v_s") == 0.1
    assert m.for_robot("pz1").all_params() == m.all_params()
    path = tmp_path / "model.yaml"
    m.dump(str(path))
    back = ActuatorModel.load(str(path))
    assert back.to_dict() == m.to_dict()
    assert back.for_robot("pz2").param("offset_rad") == 0.02
    only_robots = ActuatorModel.from_dict({"model": {"robots": {"pz1": {"effects": [
        {"name": "input_delay", "params": {"delay_s": 0.2}}]}}}})
    assert only_robots.has_effects() and not only_robots.effects


@pytest.mark.parametrize("data, fragment", [
    ({"robots": [{"name": "pz1"}]}, "robots: expected a mapping"),
    ({"robots": {"pz1": {"effects": [{"name": "input_delay", "params": {}}]}}}, "robots.pz1.effects[0]"),
    ({"robots": {"pz1": {"robots": {}}}}, "robots.pz1: unknown key(s) robots"),
    ({"effects": [{"name": "accel_limit", "params": {"a_v": -math.inf, "a_w": 1.0}}]}, "finite number"),
    ({"effects": [{"name": "gain_drift", "params": {"rate_per_s": math.inf}}]}, "finite number"),
])
def test_bad_per_robot_and_new_effect_entries(data, fragment):
    with pytest.raises(ConfigError) as e:
        ActuatorModel.from_dict(data)
    assert fragment in str(e.value)
