"""Robot emulator core: emulated ESP8266 clients and robots (no ROS).

An :class:`EmulatedRobot` turns the PWM lines it receives into motion:
PWM -> per-wheel motor (delay, deadband, gain, imbalance, first-order lag;
params.MotorParams) -> wheel rim speeds -> body velocity
(puzzlebot_common.kinematics.body_velocity) -> pose (exact arc,
puzzlebot_common.model.unicycle_arc). Its mocap pose is the true pose plus
seeded Gaussian noise.

An :class:`EmulatedClient` plays the robot's ESP8266: a TCP client that
connects to the driver from ``<source_prefix><ip_octet>`` (on loopback every
127.x.y.z address is local, so the driver sees the lab's octets), parses
the PWM lines and hands them to the robot. It reconnects when the link
drops; faults (dropping the link, sending garbage) can be injected.
"""

import logging
import math
import socket
import threading
import time
from collections import deque

import numpy as np

from puzzlebot_common.geometry import wrap_angle
from puzzlebot_common.kinematics import body_velocity
from puzzlebot_driver.protocol import ProtocolError, parse_pwm
from puzzlebot_common.model import unicycle_arc

_LOG = logging.getLogger("puzzlebot_driver.emulator")
_MAX_LINE = 64          # bytes without a newline: dropped as one garbage line


class MotorModel:
    """One wheel: PWM (with its arrival time) -> rim speed [m/s]."""

    def __init__(self, params, factor):
        self.p = params
        self.k = params.mps_per_pwm * params.gain * factor   # m/s per PWM beyond the deadband
        self._queue = deque()                                 # (t_effective, pwm)
        self.pwm = 0                                          # PWM in force (after the delay)
        self.speed = 0.0                                      # m/s

    def command(self, t, pwm):
        self._queue.append((t + self.p.delay, pwm))

    def target(self):
        """Steady rim speed for the PWM in force."""
        excess = abs(self.pwm) - self.p.deadband
        return 0.0 if excess <= 0 else math.copysign(self.k * excess, self.pwm)

    def advance(self, t, dt):
        """Rim speed over [t, t + dt) (the lag is integrated exactly for piecewise-constant PWM)."""
        while self._queue and self._queue[0][0] <= t + 1e-12:
            self.pwm = self._queue.popleft()[1]
        target = self.target()
        if self.p.tau <= 0:
            self.speed = target
        else:
            self.speed += (target - self.speed) * (1.0 - math.exp(-dt / self.p.tau))
        return self.speed


class EmulatedRobot:
    """A differential-drive robot driven by PWM lines (left, right)."""

    def __init__(self, name, params, pose, rng=None):
        self.name = name
        self.params = params
        half = 0.5 * params.imbalance
        self.left = MotorModel(params, 1.0 - half)
        self.right = MotorModel(params, 1.0 + half)
        self.pose = np.array(pose, dtype=float)       # x, y, yaw (true, world frame)
        self.v = 0.0                                   # true body velocity
        self.w = 0.0
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.last_pwm = (0, 0)
        self.last_pwm_time = None

    def command(self, t, left, right):
        """A PWM line arrived at time t."""
        self.left.command(t, left)
        self.right.command(t, right)
        self.last_pwm, self.last_pwm_time = (left, right), t

    def step(self, t, dt):
        """Advance the true state from t to t + dt."""
        v_l, v_r = self.left.advance(t, dt), self.right.advance(t, dt)
        self.v, self.w = body_velocity(v_l, v_r, self.params.wheel_base)
        x, y, th = unicycle_arc(self.pose, self.v, self.w, dt)
        self.pose = np.array([x, y, wrap_angle(th)])

    def measured_pose(self, noise_xy, noise_yaw):
        """True pose plus Gaussian mocap noise (x, y, yaw)."""
        n = self.rng.normal(size=3) * np.array([noise_xy, noise_xy, noise_yaw])
        return float(self.pose[0] + n[0]), float(self.pose[1] + n[1]), wrap_angle(self.pose[2] + n[2])


def start_poses(robots, start, spacing, where="start"):
    """Start pose per robot: from ``start`` (name -> [x, y, yaw]) where given,
    else on a line along y, ``spacing`` apart, facing +x.

    ``start`` naming a robot not in the list or holding a malformed pose
    raises ConfigError.
    """
    from puzzlebot_common.errors import ConfigError

    start = start or {}
    if not isinstance(start, dict):
        raise ConfigError("%s: expected a mapping robot name -> [x, y, yaw], got %r" % (where, start))
    names = [r.name for r in robots]
    extra = sorted(set(map(str, start)) - set(names))
    if extra:
        raise ConfigError("%s: start poses for robots not in the robot list: %s" % (where, ", ".join(extra)))
    out = {}
    for i, name in enumerate(names):
        pose = start.get(name, [0.0, i * spacing, 0.0])
        if not isinstance(pose, (list, tuple)) or len(pose) != 3 or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in pose):
            raise ConfigError("%s.%s: expected [x, y, yaw] as three finite numbers, got %r" % (where, name, pose))
        out[name] = tuple(float(v) for v in pose)
    return out


class EmulatedClient:
    """The ESP8266 of one robot: TCP client of the driver, PWM lines to ``on_pwm``.

    ``on_pwm(t, left, right)`` is called from the client's thread for every
    valid line (t from ``clock``); garbage lines are logged and dropped.
    """

    def __init__(self, name, source_ip, host, port, on_pwm, clock=time.time, reconnect_period=0.5,
                 on_disconnect=None, log=None):
        self.name = name
        self.source_ip = source_ip
        self.host, self.port = host, port
        self.on_pwm = on_pwm
        self.on_disconnect = on_disconnect
        self.clock = clock
        self.reconnect_period = reconnect_period
        self._log = log or (lambda level, text: _LOG.log(
            {"info": logging.INFO, "warn": logging.WARNING, "error": logging.ERROR}[level], text))
        self._sock = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._hold_until = 0.0          # monotonic: no reconnect before this (injected link drop)
        self._thread = None
        self.connected = threading.Event()
        self.connects = 0
        self.lines = 0
        self.garbage = 0

    def start(self):
        self._thread = threading.Thread(target=self._run, name="esp_%s" % self.name, daemon=True)
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()
        self._close()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def drop(self, hold=0.0):
        """Fault: close the TCP connection now; reconnect no earlier than ``hold`` s later."""
        self._hold_until = time.monotonic() + hold
        self._close()

    def send_raw(self, data):
        """Fault: send bytes up the link (the driver must log and ignore them). False if not connected."""
        with self._lock:
            sock = self._sock
        if sock is None:
            return False
        try:
            sock.sendall(data)
            return True
        except OSError:
            return False

    def _close(self):
        with self._lock:
            sock, self._sock = self._sock, None
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()

    def _connect(self):
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            sock.bind((self.source_ip, 0))
            sock.settimeout(self.reconnect_period)
            sock.connect((self.host, self.port))
        except OSError:
            sock.close()
            return None
        sock.settimeout(0.2)
        return sock

    def _run(self):
        while not self._stop.is_set():
            wait = self._hold_until - time.monotonic()
            if wait > 0:
                self._stop.wait(min(wait, 0.1))
                continue
            sock = self._connect()
            if sock is None:
                self._stop.wait(self.reconnect_period)
                continue
            with self._lock:
                self._sock = sock
            self.connects += 1
            self.connected.set()
            self._log("info", "%s: connected to %s:%d from %s" % (self.name, self.host, self.port, self.source_ip))
            self._serve(sock)
            self.connected.clear()
            self._close()
            if self.on_disconnect is not None:
                self.on_disconnect(self.clock())
            if not self._stop.is_set():
                self._log("info", "%s: link to the driver lost; reconnecting" % self.name)

    def _serve(self, sock):
        buf = b""
        while not self._stop.is_set():
            with self._lock:
                if self._sock is not sock:
                    return
            try:
                data = sock.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                return
            if not data:
                return
            t = self.clock()
            buf += data
            *lines, buf = buf.split(b"\n")
            if len(buf) > _MAX_LINE:
                lines.append(buf)
                buf = b""
            for line in lines:
                try:
                    left, right = parse_pwm(line)
                except ProtocolError as e:
                    self.garbage += 1
                    self._log("warn", "%s: ignoring %s" % (self.name, e))
                    continue
                self.lines += 1
                self.on_pwm(t, left, right)


class EmulatedFleet:
    """N emulated robots and their ESP8266 clients, stepped by the caller.

    ``robots``: parsed robot list (names, ip_octet); ``config``:
    params.EmulatorConfig; ``starts``: name -> (x, y, yaw). Noise streams
    are seeded from ``config.params.seed`` (one independent stream per robot).
    """

    def __init__(self, robots, config, starts, clock=time.time, log=None):
        p = config.params
        self.params = p
        self.clock = clock
        streams = np.random.default_rng(p.seed).spawn(len(robots))
        self.robots = {r.name: EmulatedRobot(r.name, config.motors[r.name], starts[r.name], rng)
                       for r, rng in zip(robots, streams)}
        self.clients = {}
        for r in robots:
            robot = self.robots[r.name]
            on_disconnect = (lambda t, robot=robot: robot.command(t, 0, 0)) if p.zero_on_disconnect else None
            self.clients[r.name] = EmulatedClient(
                r.name, "%s%d" % (p.source_prefix, r.ip_octet), p.driver_host, p.port, robot.command,
                clock=clock, reconnect_period=p.reconnect_period, on_disconnect=on_disconnect, log=log)
        self.muted_until = {name: -math.inf for name in self.robots}   # clock time

    def start(self):
        for c in self.clients.values():
            c.start()
        return self

    def stop(self):
        for c in self.clients.values():
            c.stop()

    def advance(self, t, dt):
        for robot in self.robots.values():
            robot.step(t, dt)

    def mute(self, name, until):
        """Fault: no mocap pose for ``name`` until clock time ``until``."""
        self.muted_until[name] = until

    def mocap(self, t):
        """(name, (x, y, yaw)) of every robot whose mocap stream is not muted at t."""
        p = self.params
        return [(name, robot.measured_pose(p.noise_xy, p.noise_yaw)) for name, robot in self.robots.items()
                if t >= self.muted_until[name]]
