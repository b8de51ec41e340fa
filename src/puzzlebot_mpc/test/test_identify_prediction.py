"""The prediction functions of puzzlebot_common.effects and the tool's fast error metric agree.

The metric (identify/engine.py) integrates every window from one vectorised
velocity signal; the MPC will use effects.actuator_state + effects.predict.
Both must be the same model: the plant stepped at any dt, the vectorised
plant, the explicit predictor and the metric are compared here, and the metric
of the true model on noise-free data must be zero (to the error of arcs over
10 ms steps of varying velocity).
"""

import math

import numpy as np
import pytest

import identify_synth as synth
from puzzlebot_common.effects import (ActuatorModel, ActuatorPlant, actuator_state, actuator_velocities,
                                   predict)
from puzzlebot_mpc.identify import IdentifySettings, engine
from puzzlebot_mpc.identify.data import RobotData
from puzzlebot_common.model import unicycle_arc

ALL = {"input_delay": {"delay_s": 0.087}, "deadband": {"v_min": 0.01, "w_min": 0.1},
       "friction_offset": {"v_c": 0.004, "w_c": 0.05}, "velocity_scale": {"k_v": 0.9, "k_w": 1.1},
       "velocity_lag": {"tau_v_s": 0.12, "tau_w_s": 0.07}, "accel_limit": {"a_v": 0.4, "a_w": 8.0},
       "gain_drift": {"rate_per_s": -0.004}, "yaw_rate_bias": {"w_per_v": 0.5, "w0": 0.02},
       "heading_offset": {"offset_rad": 0.05}}
#: The same without the acceleration limit (the linear path of the vectorised plant).
LINEAR = {k: v for k, v in ALL.items() if k != "accel_limit"}
#: An acceleration limit without a lag (velocities ramp to their targets).
RAMP = dict(LINEAR, accel_limit={"a_v": 0.3, "a_w": 6.0}, velocity_lag={"tau_v_s": 0.0, "tau_w_s": 0.0})


def commands(seed=0, duration=12.0):
    return synth.make_commands(np.random.default_rng(seed), duration)


def step_plant(model, cmds, dt, t_end):
    plant, out, i = ActuatorPlant(model), [], 0
    for k in range(int(round(t_end / dt))):
        t = k * dt
        while i < len(cmds) and cmds[i][0] < t + dt:
            plant.command(*cmds[i])
            i += 1
        out.append(plant.advance(t, dt))
    return np.array(out)


@pytest.mark.parametrize("effects", [ALL, LINEAR, RAMP], ids=["all", "linear", "ramp"])
def test_plant_is_exact_for_any_step(effects):
    """Mean velocities over coarse steps equal the averages of fine steps: no dt dependence."""
    model, cmds = synth.model_of(effects), commands()
    fine = step_plant(model, cmds, 0.001, 10.0)
    for coarse in (0.01, 0.05):
        k = int(round(coarse / 0.001))
        np.testing.assert_allclose(step_plant(model, cmds, coarse, 10.0), fine.reshape(-1, k, 2).mean(axis=1),
                                   atol=1e-9)


def test_plant_mean_velocity_of_a_lag():
    """advance returns the exact mean of the first-order response over the step."""
    model = ActuatorModel().add("velocity_lag", {"tau_v_s": 0.2, "tau_w_s": 0.1})
    plant = ActuatorPlant(model)
    plant.command(0.0, 0.1, 1.0)
    v, w = plant.advance(0.0, 0.2)
    assert v == pytest.approx(0.1 * (1 - 0.2 / 0.2 * (1 - math.exp(-1))))
    assert w == pytest.approx(1.0 * (1 - 0.1 / 0.2 * (1 - math.exp(-2))))
    assert plant.v == pytest.approx(0.1 * (1 - math.exp(-1)))


@pytest.mark.parametrize("effects", [ALL, LINEAR, RAMP], ids=["all", "linear", "ramp"])
def test_vectorised_plant_matches_the_plant(effects):
    model, cmds = synth.model_of(effects), commands(1)
    dt, n = 0.01, 1000
    ref = step_plant(model, cmds, dt, n * dt)
    t, v, w = (np.array(c) for c in zip(*cmds))
    vv, ww = actuator_velocities(model.all_params(), t, v, w, 0.0, dt, n, initial=(0.0, 0.0))
    np.testing.assert_allclose(vv, ref[:, 0], atol=1e-12)
    np.testing.assert_allclose(ww, ref[:, 1], atol=1e-12)


def test_actuator_state_and_predict_with_the_nominal_model():
    model = ActuatorModel()
    cmds = [(0.0, 0.05, 0.5), (1.0, 0.1, -1.0)]
    state = actuator_state(model, cmds, 1.0)
    assert (state.v, state.w) == (0.1, -1.0)       # a command issued exactly at t acts at t
    out = predict(model, (0.0, 0.0, 0.3), state, [(1.5, 0.0, 0.0)], 0.25, 4)
    np.testing.assert_allclose(out[2], unicycle_arc((0.0, 0.0, 0.3), 0.1, -1.0, 0.5), atol=1e-12)
    np.testing.assert_allclose(out[4], out[2], atol=1e-12)


def test_actuator_state_holds_the_delayed_commands():
    model = ActuatorModel().add("input_delay", {"delay_s": 0.3})
    state = actuator_state(model, [(0.0, 0.05, 0.0), (1.9, 0.1, 1.0), (2.3, 0.0, 0.0)], 2.0)
    assert state.active == (0.05, 0.0) and state.pending == ((1.9, 0.1, 1.0),)
    plant = ActuatorPlant.from_state(model, state)
    assert plant.advance(2.0, 0.4) == pytest.approx((0.075, 0.5))   # switches at 2.2 s, mid-step


def noise_free_robot(effects, seed=3, duration=40.0):
    rec = synth.lab_record(effects, n_robots=1, duration=duration, seed=seed, pos_noise=0.0, yaw_noise=0.0,
                           drop=0.0)
    r = rec["pz1"]
    t, v, w = (np.array(c) for c in zip(*r["cmd"]))
    return RobotData("pz1", r["t"], r["x"], r["y"], r["yaw"], t, v, w, t_start=float(r["t"][0])), r["cmd"]


def test_metric_of_the_true_model_on_noise_free_data_is_zero():
    settings = IdentifySettings()
    robot, _ = noise_free_robot(ALL)
    model = synth.model_of(ALL)
    val = engine.robot_windows(robot, settings)
    ep, ey = engine.errors(model.all_params(), robot, val)
    assert np.max(np.abs(ep)) < 1e-5 and np.max(np.abs(ey)) < 1e-6
    ep, _ = engine.errors(ActuatorModel().all_params(), robot, val)
    assert np.sqrt(np.mean(np.abs(ep) ** 2)) > 1e-3                  # the nominal model is wrong


def test_metric_agrees_with_actuator_state_and_predict():
    """The fast metric = feeding effects.predict the previous 2 s of commands, window by window."""
    settings = IdentifySettings()
    robot, cmds = noise_free_robot(ALL, seed=4)
    model = synth.model_of(ALL)
    val = engine.robot_windows(robot, settings)
    pos, yaw = engine.predict(model.all_params(), robot, val)
    for i in range(0, len(val), 37):
        ts, te = val.ts[i], val.te[i]
        state = actuator_state(model, cmds, ts, history_s=settings.history_s)
        pose0 = (val.p_start[i].real, val.p_start[i].imag, val.yaw_start[i])
        out = predict(model, pose0, state, [c for c in cmds if c[0] <= te], te - ts, 1, max_substep=0.005,
                      t_start=robot.t_start)
        assert abs(out[1, 0] + 1j * out[1, 1] - pos[i]) < 1e-5
        assert abs(math.remainder(out[1, 2] - yaw[i], 2 * math.pi)) < 1e-6
