"""The worlds' stages: where a robot can stand, for the simulation and for the controller.

One description of the worlds, read by both sides: the simulation builds its
static Bullet bodies from :func:`stages` (puzzlebot_sim/worlds.py) and the MPC
keeps every robot's footprint on the stage it stands on (:class:`StageMap`,
MPCSettings ``edges``), from the same world name and :class:`WorldParams`.

Worlds (the ``sim.world`` parameter, a scenario's ``world``):

- ``flat``: the lab floor, no edges;
- ``step``: a stage (top at ``stage_height``) for ``edge_x - stage_length <=
  x <= edge_x``, ``|y| <= stage_width / 2``, the floor below and beyond it;
- ``gap``: that stage and a second one of the same size from ``edge_x +
  gap_width``, the floor between them.

The floor has no edges. Units: metres; world frame, z up.
"""

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import from_mapping, require_positive

WORLD_NAMES = ("flat", "step", "gap")


@dataclass(frozen=True)
class WorldParams:
    """Dimensions of the worlds (puzzlebot_sim config/sim.yaml, ``world``).

    ``step``: a stage (top at ``stage_height``) covering x < ``edge_x``, the
    floor below it. ``gap``: two stages of ``stage_height``, one for
    x < ``edge_x``, the other for x > ``edge_x`` + ``gap_width``.
    """

    floor_friction: float = 1.0      # -
    stage_height: float = 0.05       # m, at least one robot height
    edge_x: float = 0.0              # m, x of the (first) stage's edge
    stage_length: float = 0.6        # m, stage extent in x
    stage_width: float = 0.6         # m, stage extent in y (centred on y = 0)
    gap_width: float = 0.04          # m, gap between the two stages of the gap world

    @classmethod
    def from_dict(cls, data, where="world"):
        return from_mapping(cls, data, where)

    def check(self, where="world"):
        require_positive(self, ["stage_height", "stage_length", "stage_width", "gap_width"], where)
        if self.floor_friction < 0:
            raise ConfigError("%s: floor_friction must be >= 0, got %r" % (where, self.floor_friction))


@dataclass(frozen=True)
class Stage:
    """A raised rectangle, axis-aligned in the world frame: x_min..x_max, y_min..y_max [m], top at ``height``."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float
    height: float

    def contains(self, x, y):
        return self.x_min <= x <= self.x_max and self.y_min <= y <= self.y_max


def stages(world, params=None):
    """The stages of world ``world`` (a name of WORLD_NAMES) with dimensions ``params`` (WorldParams)."""
    if world not in WORLD_NAMES:
        raise ConfigError("unknown world %r; known worlds: %s" % (world, ", ".join(WORLD_NAMES)))
    w = params or WorldParams()
    half = w.stage_width / 2.0
    first = Stage(w.edge_x - w.stage_length, w.edge_x, -half, half, w.stage_height)
    if world == "flat":
        return []
    if world == "step":
        return [first]
    x0 = w.edge_x + w.gap_width
    return [first, Stage(x0, x0 + w.stage_length, -half, half, w.stage_height)]


class StageMap:
    """Which stage a robot stands on, and the box its base_link must keep to stay on it.

    ``margin`` [m]: how far inside a stage's edges the base_link stays (the
    controller uses the footprint's circumradius: the body square is on the
    stage whatever the heading).
    """

    def __init__(self, stage_list, margin):
        if margin < 0 or not math.isfinite(margin):
            raise ValueError("margin must be finite and >= 0, got %r" % margin)
        self.stages: List[Stage] = list(stage_list)
        self.margin = float(margin)

    @classmethod
    def of_world(cls, world, params, margin):
        return cls(stages(world, params), margin)

    def __bool__(self):
        return bool(self.stages)

    def stage_at(self, x, y) -> Optional[Stage]:
        """The highest stage under (x, y) [m], None on the floor."""
        under = [s for s in self.stages if s.contains(x, y)]
        return max(under, key=lambda s: s.height) if under else None

    def height(self, x, y):
        """Surface height [m] at (x, y): a stage's top, 0 on the floor."""
        s = self.stage_at(x, y)
        return s.height if s else 0.0

    def box(self, x, y) -> Tuple[float, float, float, float]:
        """(x_lo, x_hi, y_lo, y_hi) [m] the base_link of a robot at (x, y) stays in: its stage shrunk by
        the margin; infinite on the floor (no edges). A stage narrower than twice the margin gives its
        centre line."""
        s = self.stage_at(x, y)
        if s is None:
            return (-math.inf, math.inf, -math.inf, math.inf)
        m = self.margin
        xl, xh = s.x_min + m, s.x_max - m
        yl, yh = s.y_min + m, s.y_max - m
        if xl > xh:
            xl = xh = 0.5 * (s.x_min + s.x_max)
        if yl > yh:
            yl = yh = 0.5 * (s.y_min + s.y_max)
        return (xl, xh, yl, yh)
