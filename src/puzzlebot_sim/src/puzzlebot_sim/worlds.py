"""Static worlds: the floor, a stage with an edge, two stages with a gap (puzzlebot_common.stages).

A builder creates the static bodies in a physics client and returns a
:class:`Terrain`: the body ids and the height of the walkable surface under a
point, which places robots on the right level at start-up.
"""

import os
from dataclasses import dataclass
from typing import Callable, List

import pybullet as pb
import pybullet_data

from puzzlebot_common.stages import WORLD_NAMES, StageMap, stages


@dataclass
class Terrain:
    bodies: List[int]
    height: Callable[[float, float], float]    # surface height [m] at (x, y); the floor is 0
    description: str


def _floor(client, friction):
    plane = pb.loadURDF(os.path.join(pybullet_data.getDataPath(), "plane.urdf"), physicsClientId=client)
    pb.changeDynamics(plane, -1, lateralFriction=friction, physicsClientId=client)
    return plane


def _stage(client, stage, friction):
    """A static box of puzzlebot_common.stages.Stage ``stage``."""
    half = [(stage.x_max - stage.x_min) / 2.0, (stage.y_max - stage.y_min) / 2.0, stage.height / 2.0]
    centre = [(stage.x_min + stage.x_max) / 2.0, (stage.y_min + stage.y_max) / 2.0, stage.height / 2.0]
    shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client)
    visual = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=[0.75, 0.7, 0.6, 1],
                                  physicsClientId=client)
    body = pb.createMultiBody(0, shape, visual, centre, physicsClientId=client)
    pb.changeDynamics(body, -1, lateralFriction=friction, physicsClientId=client)
    return body


def _build(name, description):
    """A builder of world ``name``: the floor and the stages of puzzlebot_common.stages.stages."""
    def build(client, w):
        stage_map = StageMap(stages(name, w), 0.0)
        bodies = [_floor(client, w.floor_friction)] + [_stage(client, s, w.floor_friction)
                                                        for s in stage_map.stages]
        return Terrain(bodies, stage_map.height, description(w))
    build.__name__ = name
    build.__doc__ = description.__doc__
    return build


def _flat(w):
    """The lab floor."""
    return "flat floor"


def _step(w):
    """A stage for x < edge_x (top at stage_height) and the floor beyond its edge."""
    return "stage of %.0f mm with its edge at x = %.3f m" % (1e3 * w.stage_height, w.edge_x)


def _gap(w):
    """Two stages of equal height, x < edge_x and x > edge_x + gap_width, the floor between them."""
    return ("two stages of %.0f mm with a %.0f mm gap at x = %.3f m"
            % (1e3 * w.stage_height, 1e3 * w.gap_width, w.edge_x))


#: World builders by name (the ``sim.world`` parameter; the stages: puzzlebot_common.stages).
WORLDS = {name: _build(name, d) for name, d in zip(WORLD_NAMES, (_flat, _step, _gap))}
