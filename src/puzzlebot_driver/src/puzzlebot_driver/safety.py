"""The host-side safety layer: when a robot must get zero PWM.

The robots' firmware has no command timeout (a robot keeps its last PWM
until the next line), so every stop happens here. Per robot and loop tick,
the first rule that applies wins:

===================  =======================================================
reason               rule
===================  =======================================================
``estop``            the e-stop is engaged (latched until released)
``no link``          the robot is not connected (nothing can be sent; the loop restarts clean)
``no pose``          no mocap pose received yet
``pose stale``       the latest pose's stamp is older than ``pose_timeout``
``no command``       no valid cmd_vel received yet
``command rejected`` the latest cmd_vel was NaN/inf or beyond the limits
``command stale``    the latest valid cmd_vel is older than ``cmd_timeout``
``stop``             the command is (near) zero: |v| < v_stop and |w| < w_stop
``drive``            none of the above: the velocity loop runs
===================  =======================================================

While driving, the loop itself falls back to zero (driver.DriverCore.tick):

=====================  =====================================================
``estimate invalid``   the velocity estimate is non-finite or beyond the pose gate's
                       speed / turn-rate bounds (the estimate restarts)
``output invalid``     the PWM came out non-finite (never sent, never rounded)
``internal error``     the robot's step raised an arithmetic or value error (logged; the
                       other robots are served)
=====================  =====================================================

Every reason but ``drive`` means PWM 0 on both wheels and a reset of the
robot's integrators.
"""

import math

ESTOP = "estop"
NO_LINK = "no link"
NO_POSE = "no pose"
POSE_STALE = "pose stale"
NO_COMMAND = "no command"
COMMAND_REJECTED = "command rejected"
COMMAND_STALE = "command stale"
STOP = "stop"
DRIVE = "drive"
ESTIMATE_INVALID = "estimate invalid"
OUTPUT_INVALID = "output invalid"
INTERNAL_ERROR = "internal error"


def check_command(v, w, params):
    """None if (v, w) may be executed, else the reason it is rejected."""
    if not (isinstance(v, (int, float)) and isinstance(w, (int, float))
            and math.isfinite(v) and math.isfinite(w)):
        return "non-finite command (v=%r, w=%r)" % (v, w)
    if abs(v) > params.v_limit:
        return "|v| = %.3f m/s exceeds v_limit %.3f m/s" % (abs(v), params.v_limit)
    if abs(w) > params.w_limit:
        return "|w| = %.3f rad/s exceeds w_limit %.3f rad/s" % (abs(w), params.w_limit)
    return None


def zero_reason(now, estop, pose_stamp, cmd, cmd_time, cmd_rejected, params, linked=True):
    """Why the robot gets zero PWM at time ``now`` [s], or DRIVE.

    ``pose_stamp``: stamp of the latest accepted pose (None if none);
    ``cmd``: latest (v, w) accepted, ``cmd_time``: when it arrived (None if
    none); ``cmd_rejected``: the latest command was rejected; ``linked``:
    the robot is connected.
    """
    if estop:
        return ESTOP
    if not linked:
        return NO_LINK
    if pose_stamp is None:
        return NO_POSE
    if now - pose_stamp > params.pose_timeout:
        return POSE_STALE
    if cmd_rejected:
        return COMMAND_REJECTED
    if cmd is None or cmd_time is None:
        return NO_COMMAND
    if now - cmd_time > params.cmd_timeout:
        return COMMAND_STALE
    if abs(cmd[0]) < params.v_stop and abs(cmd[1]) < params.w_stop:
        return STOP
    return DRIVE
