"""The sim node's loop timing: what falls on a physics step, and wall-clock pacing (ROS-free).

Rates come from SimParams (config/sim.yaml): poses (vicon, tf and /clock)
every physics_rate / pose_rate steps, the physical pairs every
physics_rate / pairs_rate steps, the joint states every physics_rate /
joint_state_rate steps, the lockstep handshake every sync_period
(with sync_topic set; step 0 included). ``pace`` holds the loop to
real_time_factor x wall-clock speed (0: as fast as possible).
"""

from puzzlebot_sim.wall_clock import WallClock


class Stepper:
    """Per-step schedule and pacing of the sim node's loop; wall time from ``clock`` (default WallClock),
    counted from the Stepper's creation."""

    def __init__(self, sim, clock=None):
        self.pose_every = sim.physics_rate // sim.pose_rate            # physics steps
        self.pairs_every = sim.physics_rate // sim.pairs_rate          # physics steps
        self.joints_every = sim.physics_rate // sim.joint_state_rate   # physics steps
        self.sync_every = int(round(sim.sync_period * sim.physics_rate)) if sim.sync_topic else 0
        self.real_time_factor = sim.real_time_factor
        self._clock = clock if clock is not None else WallClock()
        self._wall0 = self._clock.now()

    def poses_due(self, step):
        """True when physics step ``step`` publishes the poses and the clock."""
        return step % self.pose_every == 0

    def pairs_due(self, step):
        """True when physics step ``step`` publishes the physical pairs."""
        return step % self.pairs_every == 0

    def joints_due(self, step):
        """True when physics step ``step`` publishes the joint states."""
        return step % self.joints_every == 0

    def sync_due(self, step):
        """True when physics step ``step`` waits for the controller (lockstep on)."""
        return self.sync_every > 0 and step % self.sync_every == 0

    def pace(self, sim_time):
        """Sleep until the wall time since the start reaches ``sim_time`` / real_time_factor [s].

        Returns how far [s, wall] the loop is behind that pace (0 when on time or unpaced): the
        step overran its wall-clock budget (health.SimHealth counts it)."""
        if self.real_time_factor > 0:
            ahead = sim_time / self.real_time_factor - (self._clock.now() - self._wall0)
            if ahead > 0:
                self._clock.sleep(ahead)
                return 0.0
            return -ahead
        return 0.0
