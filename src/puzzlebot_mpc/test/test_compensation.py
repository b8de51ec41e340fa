"""Planning with identified actuator effects (puzzlebot_mpc/compensation.py), checked on exact plants."""

import math

import numpy as np
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.behaviors import BehaviorRequest
from puzzlebot_mpc.compensation import Compensation, NullCompensation, load_model
from puzzlebot_mpc.control_loop import ControlLoop
from puzzlebot_mpc.controller import MPCResult
from puzzlebot_common.effects import ActuatorModel, ActuatorPlant
from puzzlebot_common.model import unicycle_arc
from puzzlebot_mpc.settings import MPCSettings

SETTINGS = MPCSettings()
PLANT_DT = 0.001   # s, exact-arc steps of the test plant


def lab_model(**extra):
    m = ActuatorModel()
    m.add("input_delay", {"delay_s": 0.15})
    m.add("velocity_lag", {"tau_v_s": 0.1, "tau_w_s": 0.08})
    m.add("yaw_rate_bias", {"w_per_v": 1.5, "w0": 0.04})
    m.add("heading_offset", {"offset_rad": 0.05})
    m.add("velocity_scale", {"k_v": 0.9, "k_w": 1.1})
    for name, params in extra.items():
        m.add(name, params)
    return m


class Robot:
    """An exact plant: the effects (ActuatorPlant) and unicycle arcs; poses as the mocap measures them."""

    def __init__(self, model, pose=(0.0, 0.0, 0.3)):
        self.plant = ActuatorPlant(model)
        self.pose = np.array(pose, float)
        self.t = 0.0

    def command(self, v, w):
        self.plant.command(self.t, v, w)

    def run(self, seconds):
        for _ in range(int(round(seconds / PLANT_DT))):
            v, w = self.plant.advance(self.t, PLANT_DT)
            self.pose = unicycle_arc(self.pose, v, w, PLANT_DT)
            self.t = round(self.t + PLANT_DT, 9)

    def measured(self):
        return self.pose[0], self.pose[1], self.plant.measured_yaw(self.pose[2])


def drive_randomly(robot, comp, seconds, rng, name="r"):
    """Random commands every dt, sent to the robot and recorded by the compensation."""
    for _ in range(int(round(seconds / SETTINGS.dt))):
        v, w = rng.uniform(-0.05, 0.05), rng.uniform(-1.0, 1.0)
        robot.command(v, w)
        comp.record(name, robot.t, v, w)
        robot.run(SETTINGS.dt)


def test_empty_or_absent_model_is_the_plain_controller():
    assert isinstance(Compensation.create(None, ["r"], SETTINGS), NullCompensation)
    assert isinstance(Compensation.create(ActuatorModel(), ["r"], SETTINGS), NullCompensation)
    assert not ControlLoop(["r"], SETTINGS, actuator_model=ActuatorModel()).compensation.active

    def run(**kw):
        loop = ControlLoop(["a", "b"], SETTINGS, **kw)
        poses = {"a": np.array([0.0, 0.0, 0.2]), "b": np.array([0.0, 0.2, -2.0])}
        loop.request(BehaviorRequest("go_to_goal", ["a", "b"], [(0.15, 0.05), (0.1, 0.3)]), 0.0)
        cmds = []
        for k in range(30):
            for n, p in poses.items():
                loop.on_pose(n, 0.1 * k, *p)
            out = loop.step(0.1 * k)
            cmds.append([out.commands[n] for n in ("a", "b")])
            for n in poses:
                poses[n] = unicycle_arc(poses[n], *out.commands[n], 0.1)
        return np.array(cmds)

    plain = run()
    assert np.abs(plain).max() > 0.01
    np.testing.assert_array_equal(run(actuator_model=None), plain)
    np.testing.assert_array_equal(run(actuator_model=ActuatorModel()), plain)


def test_heading_offset_is_removed_from_measured_yaw():
    loop = ControlLoop(["r"], SETTINGS, actuator_model=ActuatorModel().add("heading_offset", {"offset_rad": 0.05}))
    loop.on_pose("r", 0.0, 0.1, 0.2, math.pi - 0.01)
    assert loop.fresh_poses(0.0)["r"] == pytest.approx((0.1, 0.2, math.pi - 0.06))


@pytest.mark.parametrize("stamp_lag", [0.0, 0.03])
def test_predicted_initial_state_is_the_plant_state_when_the_new_command_acts(stamp_lag):
    """From a measured pose and the commands sent, the state the MPC plans from is where the plant is
    (and how fast it moves) at now + delay, when the command chosen now starts to act."""
    model = lab_model()
    rng = np.random.default_rng(4)
    robot = Robot(model)
    comp = Compensation(model, ["r"], SETTINGS)
    drive_randomly(robot, comp, 3.0, rng)
    robot.run(SETTINGS.dt - stamp_lag)      # the pose is measured stamp_lag before the control step
    stamp = robot.t
    mx, my, myaw = robot.measured()
    now = stamp + stamp_lag
    x0 = np.zeros((1, 5))
    x0[0, :3] = mx, my, comp.body_yaw("r", stamp, myaw)
    comp.initial_states(x0, now, {"r": stamp})
    robot.run(now + 0.15 - robot.t)         # nothing sent at now acts before now + delay
    state = robot.plant.state(robot.t)
    np.testing.assert_allclose(x0[0, :2], robot.pose[:2], atol=2e-6)
    assert x0[0, 2] == pytest.approx(robot.pose[2], abs=2e-5)
    assert x0[0, 3] == pytest.approx(state.v, abs=1e-9)
    assert x0[0, 4] == pytest.approx(state.w + 1.5 * state.v + 0.04, abs=1e-9)


NEW_EFFECTS = {"friction_offset": {"v_c": 0.005, "w_c": 0.1}, "gain_drift": {"rate_per_s": -0.002},
               "accel_limit": {"a_v": 0.4, "a_w": 6.0}}


@pytest.mark.parametrize("lag, extra", [(True, {}), (False, {}), (True, NEW_EFFECTS)],
                         ids=["lag", "no lag", "lag, friction, drift, limit"])
def test_inverse_chain_gives_the_planned_velocity(lag, extra):
    """The command for a planned (v, w), sent now, makes the plant's body velocity equal to the plan:
    at the end of its control period with a lag (deadbeat), over the whole period without one."""
    model = lab_model(**extra) if lag else lab_model(velocity_lag={"tau_v_s": 0.0, "tau_w_s": 0.0})
    rng = np.random.default_rng(7)
    for trial in range(5):
        robot = Robot(model)
        comp = Compensation(model, ["r"], SETTINGS)
        drive_randomly(robot, comp, 2.0, rng)
        x0 = np.zeros((1, 5))
        x0[0, :3] = robot.pose[0], robot.pose[1], robot.pose[2]
        comp.robot("r").t_start = 0.0                 # the plant's drifting gain starts at 0
        comp.initial_states(x0, robot.t, {"r": robot.t})
        plan = (x0[0, 3] + rng.uniform(-0.008, 0.008), x0[0, 4] + rng.uniform(-0.1, 0.1))
        v_cmd, w_cmd = comp.invert("r", *plan, now=robot.t)
        assert abs(v_cmd) < SETTINGS.v_max and abs(w_cmd) < SETTINGS.w_max      # not clipped
        robot.command(v_cmd, w_cmd)
        robot.run(0.15)                               # the delay: the new command starts to act now
        t0 = robot.t
        mean_v, mean_w = robot.plant.advance(t0, SETTINGS.dt)
        if lag:
            end = robot.plant.velocity(t0 + SETTINGS.dt)
            g_mid = robot.plant.gain(t0 + 0.5 * SETTINGS.dt) / robot.plant.gain(t0 + SETTINGS.dt)
            assert end[0] * g_mid == pytest.approx(plan[0], abs=1e-9)
            assert end[1] - (end[0] - end[0] * g_mid) * 1.5 == pytest.approx(plan[1], abs=2e-4)
        else:
            assert (mean_v, mean_w) == pytest.approx(plan, abs=1e-9)


def test_commands_respect_limits_deadband_and_zero_plans():
    model = lab_model(deadband={"v_min": 0.01, "w_min": 0.2})
    comp = Compensation(model, ["r"], SETTINGS)
    assert comp.invert("r", 0.0, 0.0) == (0.0, 0.0)                   # at rest: exactly zero, no bias fix
    v, w = comp.invert("r", 0.05, 1.5)                                  # from rest: needs more than the limits
    assert (v, w) == (SETTINGS.v_max, SETTINGS.w_max)
    comp.robot("r").lagged = (0.002, 0.0)
    v, _ = comp.invert("r", 0.002, 0.0)                                 # 0.002 / 0.9 < v_min / 2: nothing
    assert v == 0.0
    comp.robot("r").lagged = (0.006, 0.0)
    v, _ = comp.invert("r", 0.006, 0.0)                                 # 0.0067 >= v_min / 2: the band's edge
    assert v == pytest.approx(0.01)
    result = MPCResult(np.array([[0.03, 0.2]]), np.zeros((1, 11, 5)), False, "failed", 0.0, 0, float("nan"),
                       fallback="stop")
    comp.to_commands(result, 1.0)
    assert result.commands.tolist() == [[0.0, 0.0]]                     # a failed step stops the robot
    assert comp.sent("r")[-1] == (1.0, 0.0, 0.0)


def test_history_keeps_the_command_in_force():
    model = lab_model()
    comp = Compensation(model, ["r"], SETTINGS)
    comp.record("r", 0.0, 0.04, 0.0)
    for k in range(1, 100):
        comp.record("r", 10.0 + 0.1 * k, 0.04, 0.0)
    sent = comp.sent("r")
    part = comp.robot("r")
    assert len(sent) < 40 and sent[0][0] <= 19.9 - part.history_s - part.delay


def test_compensated_mpc_tracks_better_on_a_plant_with_effects():
    """Closed loop on the exact plant: the MPC with the true model holds goals far better."""
    model = lab_model()

    def steady_errors(actuator_model):
        loop = ControlLoop(["r"], SETTINGS, actuator_model=actuator_model)
        robot = Robot(model, pose=(0.0, 0.0, 0.0))
        errors = []
        for goal in [(0.12, 0.05), (0.05, -0.06)]:
            loop.request(BehaviorRequest("go_to_goal", ["r"], [goal], tolerance=0.0005), robot.t)
            for k in range(60):
                loop.on_pose("r", robot.t, *robot.measured())
                out = loop.step(robot.t)
                robot.command(*out.commands["r"])
                robot.run(SETTINGS.dt)
            errors.append(math.hypot(robot.pose[0] - goal[0], robot.pose[1] - goal[1]))
        return errors

    plain, comp = steady_errors(None), steady_errors(model)
    assert max(comp) < 0.002
    assert max(comp) < 0.5 * max(plain), (plain, comp)


def test_load_model(tmp_path):
    assert load_model("") is None
    good = tmp_path / "model.yaml"
    lab_model().dump(str(good))
    assert load_model(str(good)).names() == lab_model().names()
    empty = tmp_path / "empty.yaml"
    empty.write_text("model:\n  effects: []\n")
    assert load_model(str(empty)) is None
    with pytest.raises(ConfigError, match=r"^~actuator_model: .*missing.yaml: no such file$"):
        load_model(str(tmp_path / "missing.yaml"), where="~actuator_model")
    bad = tmp_path / "bad.yaml"
    bad.write_text("model:\n  effects:\n    - name: input_delay\n      params: {delay_s: -0.1}\n")
    with pytest.raises(ConfigError, match=r"effects\[0\]\.params\.delay_s: must be >= 0") as e:
        load_model(str(bad))
    assert "\n" not in str(e.value)
    broken = tmp_path / "broken.yaml"
    broken.write_text("model: {effects: [\n")
    with pytest.raises(ConfigError, match="not valid YAML") as e:
        load_model(str(broken))
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="expected the path"):
        load_model(3)


def test_each_robot_is_planned_with_its_own_model():
    """model.yaml robots: entries: pz2's own delay replaces the shared one, pz3 (own model empty) is
    the plain unicycle, unknown robots get the shared effects."""
    model = ActuatorModel().add("input_delay", {"delay_s": 0.15})
    model.add_for_robot("pz2", "input_delay", {"delay_s": 0.3})
    model.add_for_robot("pz3", "input_delay", {"delay_s": 0.0})
    comp = Compensation.create(model, ["pz1", "pz2", "pz3"], SETTINGS)
    assert comp.robot("pz1").delay == 0.15 and comp.robot("pz2").delay == 0.3
    assert comp.robot("pz3").delay == 0.0
    only = ActuatorModel().add_for_robot("pz2", "heading_offset", {"offset_rad": 0.1})
    comp = Compensation.create(only, ["pz1", "pz2"], SETTINGS)
    assert comp.robot("pz1") is None and comp.body_yaw("pz1", 0.0, 0.5) == 0.5
    assert comp.body_yaw("pz2", 0.0, 0.5) == pytest.approx(0.4)
    assert isinstance(Compensation.create(only, ["pz1"], SETTINGS), NullCompensation)


def test_acceleration_limited_inverse_reaches_the_plan_or_ramps():
    from puzzlebot_common.effects import lag_response
    from puzzlebot_mpc.compensation import lag_inverse

    for y0, target, tau, a in ((0.0, 0.03, 0.1, 0.4), (0.05, 0.02, 0.1, 0.4), (0.0, 0.03, 0.0, 0.4)):
        u = lag_inverse(target, y0, tau, a, 0.1)
        assert lag_response(y0, u, tau, a, 0.1)[2] == pytest.approx(target, abs=1e-9)
    u = lag_inverse(0.1, 0.0, 0.1, 0.4, 0.1)          # 0.1 m/s in 0.1 s needs 1 m/s^2: ramp all the way
    assert lag_response(0.0, u, 0.1, 0.4, 0.1)[2] == pytest.approx(0.04)
