"""Static worlds: the floor, a stage with an edge, two stages with a gap.

A builder creates the static bodies in a physics client and returns a
:class:`Terrain`: the body ids and the height of the walkable surface under a
point, which places robots on the right level at start-up.
"""

import os
from dataclasses import dataclass
from typing import Callable, List

import pybullet as pb
import pybullet_data


@dataclass
class Terrain:
    bodies: List[int]
    height: Callable[[float, float], float]    # surface height [m] at (x, y); the floor is 0
    description: str


def _floor(client, friction):
    plane = pb.loadURDF(os.path.join(pybullet_data.getDataPath(), "plane.urdf"), physicsClientId=client)
    pb.changeDynamics(plane, -1, lateralFriction=friction, physicsClientId=client)
    return plane


def _stage(client, x0, x1, w, height, friction):
    half = [(x1 - x0) / 2.0, w / 2.0, height / 2.0]
    shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client)
    visual = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=[0.75, 0.7, 0.6, 1],
                                  physicsClientId=client)
    body = pb.createMultiBody(0, shape, visual, [(x0 + x1) / 2.0, 0.0, height / 2.0], physicsClientId=client)
    pb.changeDynamics(body, -1, lateralFriction=friction, physicsClientId=client)
    return body


def flat(client, w):
    """The lab floor."""
    return Terrain([_floor(client, w.floor_friction)], lambda x, y: 0.0, "flat floor")


def step(client, w):
    """A stage for x < edge_x (top at stage_height) and the floor beyond its edge."""
    x0, x1 = w.edge_x - w.stage_length, w.edge_x
    bodies = [_floor(client, w.floor_friction), _stage(client, x0, x1, w.stage_width, w.stage_height,
                                                       w.floor_friction)]

    def height(x, y):
        return w.stage_height if x0 <= x <= x1 and abs(y) <= w.stage_width / 2 else 0.0
    return Terrain(bodies, height, "stage of %.0f mm with its edge at x = %.3f m"
                   % (1e3 * w.stage_height, w.edge_x))


def gap(client, w):
    """Two stages of equal height, x < edge_x and x > edge_x + gap_width, the floor between them."""
    a0, a1 = w.edge_x - w.stage_length, w.edge_x
    b0, b1 = w.edge_x + w.gap_width, w.edge_x + w.gap_width + w.stage_length
    bodies = [_floor(client, w.floor_friction),
              _stage(client, a0, a1, w.stage_width, w.stage_height, w.floor_friction),
              _stage(client, b0, b1, w.stage_width, w.stage_height, w.floor_friction)]

    def height(x, y):
        on = (a0 <= x <= a1 or b0 <= x <= b1) and abs(y) <= w.stage_width / 2
        return w.stage_height if on else 0.0
    return Terrain(bodies, height, "two stages of %.0f mm with a %.0f mm gap at x = %.3f m"
                   % (1e3 * w.stage_height, 1e3 * w.gap_width, w.edge_x))


#: World builders by name (the ``sim.world`` parameter).
WORLDS = {"flat": flat, "step": step, "gap": gap}
