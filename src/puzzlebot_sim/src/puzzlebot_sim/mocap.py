"""The motion-capture sensor model of the simulation: what the lab's Vicon would report.

``MocapModel`` (SimParams mocap_*; off by default) turns a robot's true pose
into a measurement: lost with probability ``dropout``, Gaussian noise on x,
y and yaw, and the marker frame turned by a heading offset. SimWorld.measure
applies it with the world's seeded RNG, adding the actuator model's heading
offset. Units: metres, radians; poses (position xyz, quaternion xyzw) in the
world frame.
"""

from dataclasses import dataclass

import pybullet as pb


@dataclass(frozen=True)
class MocapModel:
    """Measurement effects on published poses (all off by default)."""

    position_std: float = 0.0    # m, Gaussian noise on x and y
    yaw_std: float = 0.0         # rad, Gaussian noise on yaw
    dropout: float = 0.0         # probability that a measurement is lost
    heading_offset: float = 0.0  # rad, marker-frame yaw minus body yaw

    @classmethod
    def from_sim(cls, sim):
        """The model of a SimParams' mocap_* fields."""
        return cls(sim.mocap_position_std, sim.mocap_yaw_std, sim.mocap_dropout, sim.mocap_heading_offset)

    def measure(self, pose, rng, client, extra_heading_offset=0.0):
        """The measurement of true ``pose`` (position, quaternion), or None if dropped.

        ``rng``: a numpy Generator (draws: dropout, then x and y noise, then yaw noise, each only when
        that effect is on); ``client``: the physics client doing the quaternion arithmetic;
        ``extra_heading_offset`` [rad]: added to ``heading_offset`` (the actuator model's).
        """
        if self.dropout > 0.0 and rng.random() < self.dropout:
            return None
        pos, orn = pose
        offset = self.heading_offset + extra_heading_offset
        if offset == 0.0 and self.position_std == 0.0 and self.yaw_std == 0.0:
            return pos, orn
        x, y, z = pos
        if self.position_std > 0.0:
            dx, dy = rng.normal(0.0, self.position_std, 2)
            x, y = x + dx, y + dy
        dyaw = offset + (rng.normal(0.0, self.yaw_std) if self.yaw_std > 0.0 else 0.0)
        rot = pb.getQuaternionFromEuler([0, 0, dyaw])
        orn = pb.multiplyTransforms([0, 0, 0], rot, [0, 0, 0], orn, physicsClientId=client)[1]
        return (x, y, z), orn
