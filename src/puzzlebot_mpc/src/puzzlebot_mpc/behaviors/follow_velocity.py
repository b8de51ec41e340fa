"""``follow_velocity``: every named robot tracks its own (v [m/s], w [rad/s]).

The velocities must be finite and within v_max / w_max. Succeeds after
``timeout`` s (the duration; 0: runs until replaced). Progress: elapsed over
``timeout`` (NaN without one).
"""

from puzzlebot_mpc.behaviors.base import SUCCEEDED, Behavior, Progress

FOLLOW_VELOCITY = "follow_velocity"


class FollowVelocity(Behavior):
    name = FOLLOW_VELOCITY

    def validate(self, poses=None):
        for name, vel in self.one_per_robot(self.req.velocities, "velocity", "velocity(ies)"):
            self.check_velocity(name, vel)

    def start(self, now, poses, static):
        for k, name in enumerate(self.robots):
            static.velocity[self.ctx.index[name]] = self.req.velocities[k]
        return super().start(now, poses, static)

    def completion(self, errors, elapsed):
        return min(1.0, elapsed / self.req.timeout) if self.req.timeout > 0 else float("nan")

    def timed_out(self, now, poses, errors, elapsed):
        return Progress(SUCCEEDED, "followed the velocity for %.2f s" % elapsed, errors)
