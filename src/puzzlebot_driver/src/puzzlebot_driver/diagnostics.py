"""Content of the driver's diagnostics (diagnostic_msgs), without ROS.

One status per robot -- mocap rate and age, the pose gate's state and
rejection counts, link state, last PWM and why, command and estimate -- and
one for the loop (achieved rate and jitter), as puzzlebot_common.diagnostics
statuses. The node turns these into a diagnostic_msgs/DiagnosticArray on /diagnostics.
"""

from puzzlebot_common.diagnostics import OK, WARN, Status, fmt
from puzzlebot_common.pose_gate import KINDS
from puzzlebot_driver import safety


def robot_status(state, link, estimate, now, params, loop_rate=None, prefix="puzzlebot_driver"):
    """Status of one robot. ``state``: driver.RobotState; ``link``: link.LinkInfo or None;
    ``estimate``: (v, w) or None; ``now``: clock time [s]; ``loop_rate``: achieved [Hz]."""
    d = state.decision
    connected = bool(link and link.connected)
    if not connected:
        level, message = WARN, ("not connected" if not (link and link.connects) else
                                "link lost (the robot keeps its last PWM until it reconnects)")
    elif d.reason == safety.DRIVE:
        level, message = OK, "driving" + (" (PWM saturated)" if d.saturated else "")
    elif d.reason in (safety.STOP, safety.NO_COMMAND):
        level, message = OK, "stopped (%s)" % d.reason
    else:
        level, message = WARN, "zero PWM: %s" % d.reason
    age = state.pose_age(now)
    cmd = state.cmd or (None, None)
    est = estimate or (None, None)
    values = [
        ("link", "connected" if connected else "disconnected"),
        ("address", link.address if link else ""),
        ("connections", str(link.connects if link else 0)),
        ("lines sent", str(link.lines_sent if link else 0)),
        ("lines received (ignored)", str(link.lines_received if link else 0)),
        ("last link error", link.last_error if link else ""),
        ("mocap rate [Hz]", "%.1f" % state.mocap_rate()),
        ("mocap age [s]", fmt(age)),
        ("pose stale after [s]", "%.3f" % params.pose_timeout),
        ("pwm left", str(d.left)),
        ("pwm right", str(d.right)),
        ("reason", d.reason),
        ("cmd v [m/s]", fmt(cmd[0], "%.4f")),
        ("cmd w [rad/s]", fmt(cmd[1], "%.4f")),
        ("est v [m/s]", fmt(est[0], "%.4f")),
        ("est w [rad/s]", fmt(est[1], "%.4f")),
        ("rejected commands", str(state.rejected_commands)),
        ("rejected poses", str(state.rejected_poses)),
    ]
    gate = state.gate
    if gate is not None:
        values.append(("pose gate", "holding (%s)" % gate.last_rejection if gate.held else "tracking"))
        values += [("rejected poses: %s" % kind, str(gate.counts[kind])) for kind in KINDS]
        values += [("rejected poses: clock", str(state.clock_rejections)),
                   ("pose re-acquisitions", str(gate.reacquisitions)),
                   ("last pose rejection", gate.last_rejection)]
    values += [
        ("loop faults (PWM 0)", str(state.loop_faults)),
        ("pilot", str(state.pilot).lower()),
        ("loop rate [Hz]", fmt(loop_rate, "%.2f")),
    ]
    return Status("%s: %s" % (prefix, state.name), level, message,
                  "%s (ip octet %d)" % (state.name, state.ip_octet), values)


def loop_status(summary, params, estop, estop_reason, rejected_connections, prefix="puzzlebot_driver"):
    """Status of the control loop from driver.LoopStats.summary()."""
    rate = summary["rate_hz"]
    if estop:
        level, message = WARN, "E-STOP engaged (%s): every robot gets PWM 0" % (estop_reason or "no reason")
    elif rate < 0.9 * params.loop_rate:
        level, message = WARN, "loop at %.1f Hz, below 90 %% of %.1f Hz" % (rate, params.loop_rate)
    else:
        level, message = OK, "loop at %.1f Hz" % rate
    values = [("target rate [Hz]", "%.1f" % params.loop_rate), ("rate [Hz]", "%.2f" % rate)]
    values += [(key.replace("_ms", " [ms]").replace("_", " "), "%.2f" % summary[key])
               for key in ("period_mean_ms", "period_std_ms", "period_p99_ms", "period_max_ms",
                           "work_mean_ms", "work_max_ms")]
    values += [("ticks", str(summary["ticks"])), ("late ticks (> 2 periods)", str(summary["overruns"])),
               ("estop", str(estop).lower()), ("refused connections", str(rejected_connections))]
    return Status("%s: loop" % prefix, level, message, "driver", values)
