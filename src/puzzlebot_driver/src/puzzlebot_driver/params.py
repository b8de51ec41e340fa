"""Parameter sets of the driver and the emulator (units in comments; YAML in config/).

The driver's configuration (``config/driver.yaml``, ROS parameter ``~driver``)::

    driver:
      port: 8080              # node-wide settings (DriverParams)
      ...
      control: {kp_v: 0.5}    # velocity loop of every robot (ControlGains)
      pilot: {pwm_max: 180}   # overrides for pilot robots (robot list: pilot: true)
      robots:                 # overrides for single robots, by name
        p21: {trim_left: 3.0}

Gains are resolved per robot as defaults <- ``control`` <- ``pilot`` (pilot
robots only) <- ``robots.<name>``. Which robots are pilots comes from the
robot list, never from an IP address in code.
"""

from dataclasses import asdict, dataclass

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.geometry import RobotGeometry
from puzzlebot_common.hardware import MOCAP_RATE, MPS_PER_PWM, V_MAX, W_MAX
from puzzlebot_common.params import from_mapping, require_positive
from puzzlebot_common.pose_gate import PoseGateParams
from puzzlebot_driver.protocol import PWM_LIMIT


@dataclass(frozen=True)
class ControlGains:
    """Velocity loop of one robot: PI on (v, w) around a PWM feed-forward.

    The PI works in velocity units: ``v_out = v_cmd + kp_v e_v + ki_v int(e_v)``
    (same for w), then ``pwm_v = pwm_per_v v_out``, ``pwm_w = pwm_per_w w_out``
    and left = pwm_v - pwm_w + trim_left, right = pwm_v + pwm_w + trim_right.
    """

    kp_v: float = 1.0            # -, proportional gain on the v error
    ki_v: float = 3.0            # 1/s, integral gain on the v error
    kp_w: float = 1.0            # -, proportional gain on the w error
    ki_w: float = 3.0            # 1/s, integral gain on the w error
    i_max_v: float = 0.05        # m/s, anti-windup clamp of ki_v * int(e_v)
    i_max_w: float = 1.0         # rad/s, anti-windup clamp of ki_w * int(e_w)
    pwm_per_v: float = 1428.6    # PWM per m/s on both wheels (lab: 1/0.0007)
    pwm_per_w: float = 28.6      # PWM per rad/s, added right / subtracted left (see docs/driver.md)
    trim_left: float = 0.0       # PWM added to the left wheel while driving
    trim_right: float = 0.0      # PWM added to the right wheel while driving
    pwm_deadband: float = 0.0    # PWM added in the direction of motion to a moving wheel
    pwm_max: int = PWM_LIMIT     # |PWM| cap per wheel (<= 250; pilots lower near stage edges)

    @classmethod
    def from_dict(cls, data, where="control"):
        return from_mapping(cls, data, where)

    def check(self, where="control"):
        for key in ("kp_v", "ki_v", "kp_w", "ki_w", "i_max_v", "i_max_w", "pwm_deadband"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0, got %r" % (where, key, getattr(self, key)))
        require_positive(self, ["pwm_per_v", "pwm_per_w"], where)
        if not 0 < self.pwm_max <= PWM_LIMIT:
            raise ConfigError("%s.pwm_max: must be in 1..%d (the firmware's range), got %r"
                              % (where, PWM_LIMIT, self.pwm_max))
        for key in ("trim_left", "trim_right", "pwm_deadband"):
            if abs(getattr(self, key)) >= self.pwm_max:
                raise ConfigError("%s.%s: |%r| must be below pwm_max (%d)"
                                  % (where, key, getattr(self, key), self.pwm_max))


@dataclass(frozen=True)
class DriverParams:
    """Driver node settings (``driver`` mapping of config/driver.yaml, minus the gains)."""

    port: int = 8080                  # TCP port the robots connect to
    bind_address: str = "0.0.0.0"     # interface to listen on ("0.0.0.0": all)
    loop_rate: float = 30.0           # Hz, velocity loop and PWM lines
    pose_timeout: float = 0.2         # s, pose older than this (by its stamp) -> zero PWM
    cmd_timeout: float = 0.5          # s, cmd_vel older than this -> zero PWM
    v_limit: float = V_MAX            # m/s, |v| above is rejected (the hardware limit)
    w_limit: float = W_MAX            # rad/s, |w| above is rejected (the hardware limit)
    v_stop: float = 0.001             # m/s, |v| below and |w| below w_stop = a stop: PWM 0
    w_stop: float = 0.01              # rad/s, see v_stop
    max_clock_skew: float = 0.05      # s, a pose stamped further in the future is rejected
    estimator_window: float = 0.05    # s, span of the finite difference over mocap poses
    estimator_tau: float = 0.03       # s, low-pass time constant of the estimate (0: none)
    estimator_max_gap: float = 0.2    # s, a longer gap between poses restarts the estimate
    mocap_rate_window: float = 1.0    # s, window of the reported mocap rate
    diagnostics_rate: float = 1.0     # Hz, /diagnostics
    keepalive_idle: float = 2.0       # s, TCP keepalive: a silent dead robot is dropped after idle + count x interval
    keepalive_interval: float = 1.0   # s, between keepalive probes
    keepalive_count: int = 3          # unanswered probes before the link is dropped
    ack_timeout: float = 3.0          # s, data unacknowledged this long drops the link (TCP_USER_TIMEOUT)
    send_stall_timeout: float = 1.0   # s, a robot that accepts no data this long is disconnected

    @classmethod
    def from_dict(cls, data, where="driver"):
        return from_mapping(cls, data, where)

    def check(self, where="driver"):
        require_positive(self, ["loop_rate", "pose_timeout", "cmd_timeout", "v_limit", "w_limit",
                                "estimator_window", "estimator_max_gap", "mocap_rate_window",
                                "diagnostics_rate", "keepalive_idle", "keepalive_interval",
                                "keepalive_count", "ack_timeout", "send_stall_timeout"], where)
        if not 0 <= self.port <= 65535:
            raise ConfigError("%s.port: expected 0..65535, got %r" % (where, self.port))
        for key in ("v_stop", "w_stop", "estimator_tau", "max_clock_skew"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0" % (where, key))
        if self.estimator_max_gap <= self.estimator_window:
            raise ConfigError("%s.estimator_max_gap (%g s) must exceed estimator_window (%g s)"
                              % (where, self.estimator_max_gap, self.estimator_window))

    @property
    def period(self):
        """Loop period [s]."""
        return 1.0 / self.loop_rate


_GAIN_SECTIONS = ("control", "pilot", "robots")


@dataclass(frozen=True)
class DriverConfig:
    """Everything the driver reads: node settings and gains resolved per robot."""

    params: DriverParams
    gains: dict          # robot name -> ControlGains
    unused_overrides: tuple = ()   # names under ``robots`` that are not in the robot list
    pose_gate: PoseGateParams = PoseGateParams()   # margins of the mocap pose gate (~pose_gate)


def _mapping(data, where):
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError("%s: expected a mapping, got %r" % (where, data))
    return data


def driver_config(data, robots, where="driver", pose_gate=PoseGateParams()):
    """Parse the ``driver`` mapping for a parsed robot list (puzzlebot_common.robots).

    ``pose_gate``: the pose gate's margins (puzzlebot_common/config/pose_gate.yaml,
    parsed by the caller); the gate's speed and turn-rate bounds are
    ``v_limit`` and ``w_limit`` times its ``speed_margin``.

    Raises ConfigError naming the key on any malformed entry and if a robot
    of the list has no ``ip_octet`` (the driver could not tell its link).
    """
    data = dict(_mapping(data, where))
    if "driver" in data and len(data) == 1:
        data = _mapping(data["driver"], where + ".driver")
        where += ".driver"
    sections = {k: _mapping(data.pop(k, None), "%s.%s" % (where, k)) for k in _GAIN_SECTIONS}
    params = DriverParams.from_dict(data, where)
    base = ControlGains.from_dict(sections["control"], where + ".control")
    pilot_over = sections["pilot"]
    ControlGains.from_dict(dict(asdict(base), **pilot_over), where + ".pilot")   # check the keys early
    per_robot = sections["robots"]
    gains = {}
    for spec in robots:
        if spec.ip_octet is None:
            raise ConfigError("robot %s has no ip_octet in the robot list: the driver identifies a "
                              "robot's TCP link by the last octet of its IP" % spec.name)
        values, source = asdict(base), where + ".control"
        if spec.pilot:
            values.update(pilot_over)
            source = where + ".pilot"
        own = _mapping(per_robot.get(spec.name), "%s.robots.%s" % (where, spec.name))
        if own:
            values.update(own)
            source = "%s.robots.%s" % (where, spec.name)
        gains[spec.name] = ControlGains.from_dict(values, source)
    unused = tuple(sorted(str(k) for k in set(per_robot) - {s.name for s in robots}))
    return DriverConfig(params, gains, unused, pose_gate)


# ----------------------------------------------------------------------------- emulator


@dataclass(frozen=True)
class MotorParams:
    """Emulated drive of one robot: PWM -> wheel rim speed -> unicycle.

    Per wheel: a PWM line takes effect ``delay`` s after it arrives; PWM within
    ``deadband`` does nothing; beyond it the steady wheel speed is
    ``mps_per_pwm * gain * (1 -/+ imbalance/2) * (|pwm| - deadband)`` (left -,
    right +) reached with a first-order lag ``tau``.
    """

    mps_per_pwm: float = MPS_PER_PWM  # m/s of wheel rim speed per PWM unit, nominal (the lab's figure)
    gain: float = 0.95            # -, actual / nominal motor gain
    imbalance: float = 0.04       # -, right wheel faster by this fraction of the mean
    deadband: float = 4.0         # PWM, |pwm| at or below this does not turn the wheel
    tau: float = 0.05             # s, first-order lag of the wheel speed
    delay: float = 0.03           # s, WiFi + firmware latency of a PWM line
    wheel_base: float = RobotGeometry.wheel_base  # m, distance between the wheel contact points

    @classmethod
    def from_dict(cls, data, where="motor"):
        return from_mapping(cls, data, where)

    def check(self, where="motor"):
        require_positive(self, ["mps_per_pwm", "gain", "wheel_base"], where)
        for key in ("deadband", "tau", "delay"):
            if getattr(self, key) < 0:
                raise ConfigError("%s.%s: must be >= 0" % (where, key))
        if not -1.0 < self.imbalance < 1.0:
            raise ConfigError("%s.imbalance: must be in (-1, 1), got %r" % (where, self.imbalance))


@dataclass(frozen=True)
class EmulatorParams:
    """Emulator node settings (``emulator`` mapping of config/emulator.yaml, minus motors)."""

    driver_host: str = "127.0.0.1"    # where the driver listens
    port: int = 8080                  # the driver's TCP port; 0: read it from port_param
    port_param: str = "/driver/bound_port"  # with port 0: parameter where the driver publishes its port
    port_wait: float = 30.0           # s (wall) to wait for port_param
    source_prefix: str = "127.0.0."   # robot with ip_octet N connects from <prefix>N (loopback)
    reconnect_period: float = 0.5     # s between connection attempts
    zero_on_disconnect: bool = False  # the lab firmware keeps its last PWM when the link drops
    physics_rate: float = 200.0       # Hz, integration step of the robots
    pose_rate: float = float(MOCAP_RATE)  # Hz, emulated Vicon (the lab's rate)
    noise_xy: float = 0.0002          # m, std of the mocap position noise
    noise_yaw: float = 0.002          # rad, std of the mocap yaw noise
    seed: int = 0                     # noise seed
    spacing: float = 0.15             # m, robots without a start pose wait on a line along y

    @classmethod
    def from_dict(cls, data, where="emulator"):
        return from_mapping(cls, data, where)

    def check(self, where="emulator"):
        require_positive(self, ["reconnect_period", "physics_rate", "pose_rate", "spacing", "port_wait"], where)
        if not 0 <= self.port <= 65535:
            raise ConfigError("%s.port: expected 0..65535, got %r" % (where, self.port))
        if self.noise_xy < 0 or self.noise_yaw < 0:
            raise ConfigError("%s: noise_xy and noise_yaw must be >= 0" % where)
        if self.pose_rate > self.physics_rate:
            raise ConfigError("%s.pose_rate (%g Hz) must not exceed physics_rate (%g Hz)"
                              % (where, self.pose_rate, self.physics_rate))


@dataclass(frozen=True)
class EmulatorConfig:
    params: EmulatorParams
    motors: dict          # robot name -> MotorParams


def emulator_config(data, robots, where="emulator"):
    """Parse the ``emulator`` mapping (``motor`` defaults, ``robots`` overrides by name)."""
    data = dict(_mapping(data, where))
    if "emulator" in data and len(data) == 1:
        data = _mapping(data["emulator"], where + ".emulator")
        where += ".emulator"
    motor = _mapping(data.pop("motor", None), where + ".motor")
    per_robot = _mapping(data.pop("robots", None), where + ".robots")
    params = EmulatorParams.from_dict(data, where)
    base = MotorParams.from_dict(motor, where + ".motor")
    unknown = sorted(str(k) for k in set(per_robot) - {s.name for s in robots})
    if unknown:
        raise ConfigError("%s.robots: motor overrides for robots not in the robot list: %s"
                          % (where, ", ".join(unknown)))
    motors = {}
    for spec in robots:
        if spec.ip_octet is None:
            raise ConfigError("robot %s has no ip_octet in the robot list: the emulator connects "
                              "from <source_prefix><ip_octet>" % spec.name)
        own = _mapping(per_robot.get(spec.name), "%s.robots.%s" % (where, spec.name))
        motors[spec.name] = MotorParams.from_dict(dict(asdict(base), **own),
                                                  "%s.robots.%s" % (where, spec.name)) if own else base
    return EmulatorConfig(params, motors)
