"""``drive_assembly``: the assembly of the named robots drives as one body.

The twist (v [m/s], w [rad/s]) is given in the first robot's frame (the
lead): the lead tracks (v, w), every other member the rigid-body speed at its
own position along its heading, turning as its couplings allow (a chain of
unicycles turns like a train, within the anchors' yaw freedom). Succeeds
after ``distance`` metres of the lead (or after ``timeout`` seconds when no
distance is given); fails if a coupled pair of the assembly is lost on the
way. Status errors: the distance [m] the lead has moved. Progress: that
distance over ``distance`` (without one: the elapsed time over ``timeout``).
"""

import math

import numpy as np

from puzzlebot_mpc.behaviors.base import FAILED, SUCCEEDED, Behavior, BehaviorError, Progress

DRIVE_ASSEMBLY = "drive_assembly"


class DriveAssembly(Behavior):
    name = DRIVE_ASSEMBLY
    needs_poses = True

    def validate(self, poses=None):
        req, robots = self.req, self.robots
        if len(req.velocities) != 1:
            raise BehaviorError("drive_assembly needs exactly one velocity (the assembly's twist in the "
                                "first robot's frame), got %d" % len(req.velocities))
        self.check_velocity(robots[0], req.velocities[0])
        if req.distance <= 0 and req.timeout <= 0:
            raise BehaviorError("drive_assembly needs a distance or a timeout (duration) > 0")
        if req.distance > 0 and abs(req.velocities[0][0]) < 1e-6:
            raise BehaviorError("drive_assembly: a distance needs a non-zero linear velocity")
        self.need_poses(robots[:1], poses)

    def start(self, now, poses, static):
        """The assembly: every robot coupled to a named one, in the MPC's order; the lead's start pose."""
        message = super().start(now, poses, static)
        group = set()
        for r in self.robots:
            group.update(self.ctx.assembly_of(r))
        self.lead = self.robots[0]
        self.assembly = [n for n in self.ctx.names if n in group]
        self.robots = self.assembly
        self.start_pose = np.array(poses[self.lead], float)
        self.progress = ""               # what the last step measured (for the timeout message)
        return message

    def status(self, now, poses, newly, lost, elapsed):
        failed = self.lost_while_driving(lost, self.assembly)
        if failed:
            return failed
        pose = poses.get(self.lead)
        if pose is None:
            return Progress(errors=[float("nan")])
        start = self.start_pose
        moved = math.hypot(pose[0] - start[0], pose[1] - start[1])
        self.progress = "the assembly moved %.3f m" % moved
        if self.req.distance > 0 and moved >= self.req.distance:
            return Progress(SUCCEEDED, "the assembly %s drove %.3f m in %.2f s with every pair coupled"
                            % ("+".join(self.assembly), moved, elapsed), [moved])
        return Progress(message="driving: %.3f m" % moved, errors=[moved])

    def completion(self, errors, elapsed):
        if self.req.distance > 0:
            return min(1.0, errors[0] / self.req.distance) if errors and errors[0] == errors[0] else float("nan")
        return min(1.0, elapsed / self.req.timeout)

    def timed_out(self, now, poses, errors, elapsed):
        if self.req.distance <= 0:
            return Progress(SUCCEEDED, "drove the assembly %s for %.2f s with every pair coupled"
                            % ("+".join(self.assembly), elapsed), errors)
        return Progress(FAILED, "timeout after %.2f s: %s" % (elapsed, self.progress), errors)

    def objectives(self, obj, now, poses):
        """The lead tracks the twist; the followers the rigid-body speed (v only: they turn as their
        couplings allow)."""
        if poses is None:
            return
        obj.velocity = self.velocities(poses)
        leads = set(self.req.robots[:1])   # none when the request names no robots: all turn as coupled
        for m in self.assembly:
            if m not in leads:
                obj.velocity_mask[self.ctx.index[m]] = (1.0, 0.0)

    def velocities(self, poses):
        """(N, 2) references: (v, w) for the lead, (rigid-body speed along the heading, w) for the others."""
        v, w = self.req.velocities[0]
        return self.rigid_velocities(np.zeros((len(self.ctx.names), 2)), self.lead, v, w, self.assembly, poses)
