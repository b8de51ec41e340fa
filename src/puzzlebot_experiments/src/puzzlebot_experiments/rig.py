"""Simulated force characterisation rig (paper, "Characterization of Anchors").

The paper's rig: the anchor is fixed, a linear actuator moves a probe in
0.1 mm steps against the anchor's beams, a load cell reads the force (five
readings averaged per step). Here the anchor is the simulated linkage with
its base fixed, and the probe is a copy of a robot's lips (two plates with
the mouth between their rounded ends), moved in 0.1 mm steps; the force is
the sum of the contact forces between probe and anchor along the push
direction, read after the linkage has settled at each step. It measures the
simulated anchor, it does not echo the profile table: the barb joints,
their torque law, the contact geometry and the solver all contribute.

* forward push: the probe comes from the head side (as an opening does when
  the anchor is pushed in) and moves toward the base;
* backward push: the probe starts behind the barb tips (anchor inserted) and
  moves toward the head (as when the anchor is pulled out).

Displacement 0 is first contact (geometric, from the linkage and lip
dimensions).
"""

import csv
import os
from dataclasses import dataclass
from typing import List

import numpy as np
import pybullet as pb

from puzzlebot_sim.bullet_session import BulletSession
from puzzlebot_sim.anchor import AnchorGeometry, BarbTorqueMap
from puzzlebot_sim.params import AnchorParams, RobotParams, SimParams
from puzzlebot_sim.urdf import URDF_FLAGS, anchor_urdf

STEP_MM = 0.1           # probe step (paper)
READINGS = 5            # readings averaged per step (paper)


@dataclass
class ForceProfile:
    displacement_mm: List[float]
    forward_n: List[float]
    backward_n: List[float]

    def at(self, which, mm):
        """Force [N] of curve ``which`` ('forward'/'backward') at displacement ``mm`` (interpolated)."""
        return float(np.interp(mm, self.displacement_mm, getattr(self, which + "_n")))

    def summary(self):
        return {"forward_peak_n": max(self.forward_n), "backward_at_4mm_n": self.at("backward", 4.0),
                "backward_peak_n": max(self.backward_n),
                "backward_peak_mm": self.displacement_mm[int(np.argmax(self.backward_n))]}


class ForceRig(BulletSession):
    """The rig in its own physics client (DIRECT)."""

    def __init__(self, robot_params=RobotParams(), anchor_params=AnchorParams(),
                 physics_rate=SimParams.physics_rate, solver_iterations=SimParams.solver_iterations,
                 erp=SimParams.erp, settle_s=0.05):
        self.rp, self.ap = robot_params, anchor_params
        self.dt = 1.0 / physics_rate
        self.settle_steps = max(1, int(round(settle_s * physics_rate)))
        c = self._connect(False, "puzzlebot_rig_")
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        pb.setTimeStep(self.dt, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSolverIterations=solver_iterations, erp=erp, contactERP=erp,
                                     frictionERP=erp, deterministicOverlappingPairs=1, physicsClientId=c)
        path = os.path.join(self._tmp.name, "anchor.urdf")
        with open(path, "w") as f:
            f.write(anchor_urdf(anchor_params))
        self.anchor = pb.loadURDF(path, [0, 0, 0.1], useFixedBase=True, flags=URDF_FLAGS,
                                  physicsClientId=c)
        for link in range(-1, 3):
            pb.changeDynamics(self.anchor, link, lateralFriction=anchor_params.barb_friction, physicsClientId=c)
        self.probe = self._make_probe()
        self.map = BarbTorqueMap(anchor_params, robot_params.mouth_width, robot_params.lip_depth / 2)
        self.geometry = AnchorGeometry(anchor_params)

    def _make_probe(self):
        c, p = self.client, self.rp
        r_e = p.lip_depth / 2.0
        half_slit, hz = p.slit_width / 2.0, p.mouth_height / 2.0
        shapes, positions, kinds = [], [], []
        for sign in (1, -1):
            y0 = p.mouth_width / 2 + r_e
            shapes.append(("box", [r_e, (half_slit - y0) / 2, hz]))
            positions.append([0.0, sign * (y0 + half_slit) / 2, 0.0])
            shapes.append(("cyl", r_e))
            positions.append([0.0, sign * y0, 0.0])
        kw = {"shapeTypes": [pb.GEOM_BOX if k == "box" else pb.GEOM_CYLINDER for k, _ in shapes],
              "halfExtents": [v if k == "box" else [0, 0, 0] for k, v in shapes],
              "radii": [0 if k == "box" else v for k, v in shapes],
              "lengths": [0 if k == "box" else 2 * hz for k, _ in shapes],
              "collisionFramePositions": positions}
        col = pb.createCollisionShapeArray(physicsClientId=c, **kw)
        body = pb.createMultiBody(0, col, -1, [1.0, 0, 0.1], physicsClientId=c)
        pb.changeDynamics(body, -1, lateralFriction=self.ap.barb_friction, physicsClientId=c)
        return body

    def _lip_centre_x_at_first_contact(self, which):
        """x of the probe plates' centre plane at first contact (anchor frame)."""
        a, g, r_e = self.ap, self.geometry, self.rp.lip_depth / 2.0
        if which == "forward":
            return self.map.forward_first_contact_x
        tip = g.tip_centre(a.barb_angle)
        return tip[0] + a.barb_tip_radius + r_e

    def _set_probe(self, x):
        pb.resetBasePositionAndOrientation(self.probe, [x, 0, 0.1], [0, 0, 0, 1], physicsClientId=self.client)

    def _settle_joints(self):
        """One step with the barb servos as in SimWorld; the neck is held straight (the rig clamps the anchor)."""
        a, c = self.ap, self.client
        states = pb.getJointStates(self.anchor, [0, 1, 2], physicsClientId=c)
        q = [s[0] for s in states]
        tau = self.map.max_torque(np.array(q[1:]))
        pb.setJointMotorControlArray(self.anchor, [0, 1, 2], pb.VELOCITY_CONTROL,
                                     targetVelocities=[-a.neck_servo_rate * q[0], -a.barb_servo_rate * q[1],
                                                       -a.barb_servo_rate * q[2]],
                                     forces=[1.0, float(tau[0]), float(tau[1])], physicsClientId=c)
        pb.stepSimulation(physicsClientId=c)

    def _force_x(self):
        f = 0.0
        for cp in pb.getContactPoints(self.probe, self.anchor, physicsClientId=self.client):
            f += cp[9] * cp[7][0]          # normal on the probe (B) points from anchor to probe
        return f

    def push(self, which, max_mm=5.0, step_mm=STEP_MM):
        """Force [N] on the probe along its motion at each displacement 0..max_mm."""
        if which not in ("forward", "backward"):
            raise ValueError("which must be 'forward' or 'backward'")
        c = self.client
        for j in range(3):
            pb.resetJointState(self.anchor, j, 0.0, 0.0, physicsClientId=c)
        x0 = self._lip_centre_x_at_first_contact(which)
        direction = 1.0 if which == "forward" else -1.0
        self._set_probe(x0 - direction * 1e-4)
        for _ in range(self.settle_steps):
            self._settle_joints()
        n = int(round(max_mm / step_mm))
        forces = []
        for k in range(n + 1):
            self._set_probe(x0 + direction * k * step_mm * 1e-3)
            for _ in range(self.settle_steps):
                self._settle_joints()
            readings = []
            for _ in range(READINGS):
                self._settle_joints()
                readings.append(-direction * self._force_x())
            forces.append(max(0.0, float(np.mean(readings))))
        return forces

    def run(self, max_mm=5.0, step_mm=STEP_MM):
        n = int(round(max_mm / step_mm))
        mm = [round(k * step_mm, 6) for k in range(n + 1)]
        return ForceProfile(mm, self.push("forward", max_mm, step_mm), self.push("backward", max_mm, step_mm))



def write_csv(profile, path):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["displacement_mm", "forward_n", "backward_n"])
        for row in zip(profile.displacement_mm, profile.forward_n, profile.backward_n):
            w.writerow(["%.1f" % row[0], "%.4f" % row[1], "%.4f" % row[2]])


def write_png(profile, path, anchor_params=None, robot_push_n=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(profile.displacement_mm, profile.forward_n, "-o", ms=2.5, label="forward push (into an opening), sim")
    ax.plot(profile.displacement_mm, profile.backward_n, "-o", ms=2.5, label="backward push (pull-out), sim")
    if anchor_params is not None:
        ax.plot(anchor_params.forward_profile_mm, anchor_params.forward_profile_n, "k:", lw=1,
                label="measured profile (model input)")
        ax.plot(anchor_params.backward_profile_mm, anchor_params.backward_profile_n, "k:", lw=1)
    if robot_push_n is not None:
        ax.axhline(robot_push_n, color="grey", lw=0.8, ls="--", label="robot push at full speed")
    ax.set_xlabel("probe displacement [mm]")
    ax.set_ylabel("force [N]")
    ax.set_title("Simulated anchor force characterisation")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def characterise(out_dir, robot_params=RobotParams(), anchor_params=AnchorParams(), **rig_kw):
    """Run both pushes, write out_dir/force_profile.csv and .png; return the ForceProfile."""
    os.makedirs(out_dir, exist_ok=True)
    with ForceRig(robot_params, anchor_params, **rig_kw) as rig:
        profile = rig.run()
    write_csv(profile, os.path.join(out_dir, "force_profile.csv"))
    write_png(profile, os.path.join(out_dir, "force_profile.png"), anchor_params, robot_params.push_force)
    return profile

