"""Body velocity of a robot from consecutive motion-capture poses.

Each pose comes with its measurement stamp (the Vicon message's
``header.stamp``, never the arrival time). The estimate spans ``window``
seconds of poses: between the oldest pose inside the window and the newest,
the robot turned by ``dth`` and moved by the chord ``d``. For a constant
(v, w) the chord points along the mean heading ``th0 + dth/2`` and its length
is ``2 (v/w) sin(dth/2)``, so::

    w = dth / dt,   v = (d . heading_mid) * (dth/2) / sin(dth/2) / dt

is exact on circular arcs (and on straight lines, where the factor is 1).
The raw estimate then goes through a first-order low-pass filter of time
constant ``tau`` (stamps give its step). A gap in the stream longer than
``max_gap`` restarts the estimate, so a robot that was hidden does not get a
velocity averaged over the gap.

There is no estimate until the poses span the whole ``window`` (at the
start and after every restart): a difference over two poses 10 ms apart
carries five times the noise and stamp jitter of the full window, and the
velocity loop's feedback on it kicked a robot resuming after a gap. Until
then the loop runs on feed-forward alone.
"""

import math
from collections import deque

from puzzlebot_common.geometry import wrap_angle


class VelocityEstimator:
    """(v [m/s], w [rad/s]) in the robot frame from stamped world poses."""

    def __init__(self, window, tau, max_gap):
        self.window = window
        self.tau = tau
        self.max_gap = max_gap
        self._poses = deque()        # (stamp, x, y, yaw), oldest first
        self._v = None
        self._w = None
        self.lateral = 0.0           # m/s, sideways chord speed of the last raw estimate (slip)

    def reset(self):
        self._poses.clear()
        self._v = self._w = None
        self.lateral = 0.0

    @property
    def last_stamp(self):
        return self._poses[-1][0] if self._poses else None

    def update(self, stamp, x, y, yaw):
        """Add a pose; return None if used, else why it was not (no exception)."""
        if not all(math.isfinite(v) for v in (stamp, x, y, yaw)):
            return "non-finite pose (%r, %r, %r) at %r" % (x, y, yaw, stamp)
        last = self.last_stamp
        if last is not None:
            if stamp <= last:
                return "pose stamp %.6f s is not after the previous one (%.6f s)" % (stamp, last)
            if stamp - last > self.max_gap:
                self.reset()
        self._poses.append((stamp, x, y, yaw))
        while len(self._poses) > 2 and stamp - self._poses[1][0] >= self.window:
            self._poses.popleft()
        t0, x0, y0, th0 = self._poses[0]
        dt = stamp - t0
        if dt < self.window * (1.0 - 1e-6):
            return None              # not a full window yet: no estimate
        dth = wrap_angle(yaw - th0)
        mid = th0 + 0.5 * dth
        forward = (x - x0) * math.cos(mid) + (y - y0) * math.sin(mid)
        half = 0.5 * dth
        arc = 1.0 if abs(half) < 1e-6 else half / math.sin(half)
        v_raw, w_raw = forward * arc / dt, dth / dt
        lateral = (-(x - x0) * math.sin(mid) + (y - y0) * math.cos(mid)) / dt
        if not (math.isfinite(v_raw) and math.isfinite(w_raw) and math.isfinite(lateral)):
            self.reset()
            return "non-finite velocity from the poses at %r and %r s: estimate restarted" % (t0, stamp)
        self.lateral = lateral
        if self._v is None or self.tau <= 0:
            self._v, self._w = v_raw, w_raw
        else:
            step = stamp - self._poses[-2][0]
            a = 1.0 - math.exp(-step / self.tau)
            self._v += a * (v_raw - self._v)
            self._w += a * (w_raw - self._w)
        return None

    def velocity(self):
        """Latest filtered (v, w), or None until the poses span the full window."""
        if self._v is None:
            return None
        return self._v, self._w
