"""Parameter sets of the simulation (units in comments; YAML in config/)."""

from dataclasses import dataclass

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import from_mapping, require_positive


@dataclass(frozen=True)
class RobotParams:
    """Simulated PuzzleBot body (config/robot.yaml)."""

    body_side: float = 0.05          # m
    body_height: float = 0.045       # m
    body_mass: float = 0.068         # kg
    ground_clearance: float = 0.003  # m
    wheel_radius: float = 0.010      # m
    wheel_width: float = 0.003       # m
    wheel_y: float = 0.020           # m
    wheel_mass: float = 0.002        # kg
    wheel_friction: float = 1.0      # -
    wheel_max_torque: float = 0.0025  # N m per wheel
    wheel_max_speed: float = 20.0    # rad/s
    caster_radius: float = 0.005     # m
    caster_x: float = 0.018          # m
    wheel_base: float = 0.04         # m

    @classmethod
    def from_dict(cls, data, where="robot"):
        return from_mapping(cls, data, where)

    def check(self, where="robot"):
        require_positive(self, ["body_side", "body_height", "body_mass", "wheel_radius", "wheel_width",
                                "wheel_y", "wheel_mass", "wheel_max_torque", "wheel_max_speed",
                                "caster_radius", "wheel_base"], where)
        if self.ground_clearance < 0 or self.wheel_friction < 0 or self.caster_x < 0:
            raise ConfigError("%s: ground_clearance, wheel_friction and caster_x must be >= 0" % where)
        if self.wheel_y + self.wheel_width / 2 > self.body_side / 2:
            raise ConfigError("%s: wheels (wheel_y + wheel_width/2 = %.4f m) stick out of the body "
                              "(body_side/2 = %.4f m)" % (where, self.wheel_y + self.wheel_width / 2,
                                                          self.body_side / 2))

    @property
    def body_centre_height(self):
        """Height of the body centre (base_link origin) above the floor at rest [m]."""
        return self.ground_clearance + self.body_height / 2.0


@dataclass(frozen=True)
class SimParams:
    """Sim node timing and options (config/sim.yaml)."""

    physics_rate: int = 400          # Hz, Bullet fixed step
    pose_rate: int = 100             # Hz, vicon topics and tf
    real_time_factor: float = 0.0    # 1 = wall-clock pace, 0 = as fast as possible
    cmd_timeout: float = 0.5         # s, sim time
    sync_topic: str = ""             # lockstep with a controller (empty: off)
    sync_period: float = 0.1         # s
    sync_timeout: float = 2.0        # s, wall
    sync_startup_timeout: float = 60.0  # s, wall
    world: str = "flat"
    gui: bool = False
    seed: int = 0

    @classmethod
    def from_dict(cls, data, where="sim"):
        return from_mapping(cls, data, where)

    def check(self, where="sim"):
        require_positive(self, ["physics_rate", "pose_rate", "cmd_timeout", "sync_period",
                                "sync_timeout", "sync_startup_timeout"], where)
        if self.real_time_factor < 0:
            raise ConfigError("%s.real_time_factor: must be >= 0 (0 = as fast as possible)" % where)
        if self.physics_rate % self.pose_rate:
            raise ConfigError("%s: physics_rate (%d Hz) must be an integer multiple of pose_rate (%d Hz)"
                              % (where, self.physics_rate, self.pose_rate))
        ticks = self.sync_period * self.pose_rate
        if abs(ticks - round(ticks)) > 1e-6:
            raise ConfigError("%s: sync_period (%g s) must be a whole number of pose periods (1/%d s)"
                              % (where, self.sync_period, self.pose_rate))
