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
