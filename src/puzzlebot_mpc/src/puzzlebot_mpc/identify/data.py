"""Reading measured data: a ROS 1 bag or a CSV file, into per-robot arrays.

Bag: ``/vicon/<s>/<s>`` (geometry_msgs/TransformStamped; the header stamp is
the pose time) and ``/<s>/cmd_vel`` (geometry_msgs/Twist; the bag's record
time is the command time), any number of robots, found from the topic names
(or named by a robot list, whose ``mocap`` subjects may differ from the robot
names). CSV: header ``t,robot,x,y,yaw,v_cmd,w_cmd`` (any column order, extra
columns ignored), one row per pose sample with the command in force at that
time. Every problem with the input raises :class:`DataError` with a message
that names it.
"""

import csv
import math
import os
import re
import sys
from dataclasses import dataclass, field
from typing import List

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from puzzlebot_common import names
from puzzlebot_common.geometry import wrap_angle

CSV_COLUMNS = ("t", "robot", "x", "y", "yaw", "v_cmd", "w_cmd")
CSV_COMMAND_TIME = "t_cmd"   # optional column: when the command in force on the row was issued [s]
POSE_TYPE = "geometry_msgs/TransformStamped"
CMD_TYPE = "geometry_msgs/Twist"
CSV_GAP_PERIODS = 1.5   # a gap between a robot's rows longer than this many median periods hides commands
_VICON_RE = re.compile(r"^/vicon/([^/]+)/([^/]+)$")


class DataError(ValueError):
    """The input data cannot be used; the message says why (file, robot, topic, line)."""


@dataclass
class RobotData:
    """One robot's record; times in seconds from the dataset's ``t0``.

    ``t, x, y, yaw``: pose samples (strictly increasing t; yaw as measured);
    ``cmd_t, cmd_v, cmd_w``: commands by issue time (ascending), each in force
    until the next; ``cmd_unknown``: (k, 2) time intervals in which the
    command timing is unknown (a CSV's command changed across a gap in the
    pose rows: the change, and any command in between, happened somewhere in
    the gap).
    """

    name: str
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    cmd_t: np.ndarray
    cmd_v: np.ndarray
    cmd_w: np.ndarray
    cmd_unknown: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    t_start: float = 0.0    # s: the robot's first pose sample in the file (where a drifting gain is 1)

    @property
    def duration(self):
        return float(self.t[-1] - self.t[0]) if self.t.size else 0.0


@dataclass
class Dataset:
    path: str
    robots: List[RobotData]
    t0: float          # absolute time [s] subtracted from every time
    kind: str = "bag"  # "bag" or "csv"
    exact_command_times: bool = True   # False: a CSV without t_cmd (command times to a pose period)

    def robot_names(self):
        return [r.name for r in self.robots]


def warn(msg):
    print("identify_model: warning: %s" % msg, file=sys.stderr)


def load(path, robots=None):
    """Read ``path`` (.bag or .csv). ``robots``: optional list of RobotSpec
    (puzzlebot_common.robots) selecting robots and their mocap subjects."""
    if not os.path.isfile(path):
        raise DataError("%s: no such file" % path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".bag":
        dataset = read_bag(path, robots)
    elif ext == ".csv":
        dataset = read_csv(path, robots)
    else:
        raise DataError("%s: unknown data format %r (expected a .bag or a .csv file)" % (path, ext))
    for r in dataset.robots:
        check_robot(r, path)
    return dataset


def check_robot(r, path):
    """Checks common to both formats: finite values, increasing time, commands present."""
    if r.t.size == 0:
        raise DataError("%s: robot %s has no pose samples" % (path, r.name))
    for label, arr in (("x", r.x), ("y", r.y), ("yaw", r.yaw)):
        if not np.all(np.isfinite(arr)):
            raise DataError("%s: robot %s: non-finite %s in the poses" % (path, r.name, label))
    bad = np.nonzero(np.diff(r.t) <= 0)[0]
    if bad.size:
        i = int(bad[0])
        raise DataError("%s: robot %s: pose time is not increasing (t=%.6f s follows t=%.6f s)"
                        % (path, r.name, r.t[i + 1] + 0.0, r.t[i] + 0.0))
    if r.cmd_t.size == 0 or not np.any((r.cmd_v != 0) | (r.cmd_w != 0)):
        raise DataError("%s: robot %s has no commands (no nonzero cmd_vel): nothing to identify; "
                        "select the commanded robots with --robots" % (path, r.name))


# ----------------------------------------------------------------------- bag
def _discover(topics, path):
    """Robot name -> (vicon topic, cmd topic) from topic names."""
    subjects = []
    for name, (msg_type, _) in sorted(topics.items()):
        m = _VICON_RE.match(name)
        if m and m.group(1) == m.group(2) and msg_type == POSE_TYPE:
            subjects.append(m.group(1))
    if not subjects:
        raise DataError("%s: no pose topics /vicon/<robot>/<robot> (%s) in the bag; it has: %s"
                        % (path, POSE_TYPE, ", ".join(sorted(topics)) or "no topics"))
    pairs = {}
    for s in subjects:
        cmd = names.cmd_vel_topic(s)
        if cmd not in topics:
            raise DataError("%s: robot %s has poses (%s) but no commands (%s not in the bag); "
                            "select the commanded robots with --robots"
                            % (path, s, names.vicon_topic(s), cmd))
        pairs[s] = (names.vicon_topic(s), cmd)
    for name in sorted(topics):
        if name.endswith("/cmd_vel") and name not in {c for _, c in pairs.values()}:
            warn("%s: %s has commands but no matching /vicon pose topic: ignored" % (path, name))
    return pairs


def write_messages(path, messages):
    """Write ``messages`` -- (time [s], topic, ROS message) -- to a new bag at ``path``, in time order
    (each recorded at its time: for /cmd_vel the record time is the command time, as read_bag expects)."""
    import rosbag
    import rospy

    with rosbag.Bag(path, "w") as bag:
        for t, topic, m in sorted(messages, key=lambda item: item[0]):
            bag.write(topic, m, rospy.Time.from_sec(t))


def read_bag(path, robots=None):
    """Poses and commands of a ROS 1 bag, read by the fast reader (bagfile.py: no ROS, no
    per-message Python)."""
    from puzzlebot_mpc.identify import bagfile

    if os.path.getsize(path) == 0:
        raise DataError("%s: empty file (not a ROS bag)" % path)
    try:
        topics, _ = bagfile.read(path, set())
    except (bagfile.BagError, OSError) as e:
        raise DataError("%s: not a readable ROS bag: %s" % (path, e)) from None
    if sum(count for _, count in topics.values()) == 0:
        raise DataError("%s: empty bag (no messages)" % path)
    if robots:
        pairs = {}
        for spec in robots:
            pose, cmd = spec.vicon_topic, names.cmd_vel_topic(spec.name)
            for topic in (pose, cmd):
                if topic not in topics:
                    raise DataError("%s: robot %s: topic %s is not in the bag" % (path, spec.name, topic))
            pairs[spec.name] = (pose, cmd)
    else:
        pairs = _discover(topics, path)
    for name, (pose, cmd) in pairs.items():
        for topic, wanted in ((pose, POSE_TYPE), (cmd, CMD_TYPE)):
            if topics[topic][0] != wanted:
                raise DataError("%s: robot %s: %s has type %s, expected %s"
                                % (path, name, topic, topics[topic][0], wanted))
    try:
        _, messages = bagfile.read(path, {t for pair in pairs.values() for t in pair})
    except (bagfile.BagError, OSError) as e:
        raise DataError("%s: cannot read the bag's messages: %s" % (path, e)) from None
    out = []
    for name, (pose, cmd) in pairs.items():
        if pose not in messages:
            raise DataError("%s: robot %s: no pose messages on %s" % (path, name, pose))
        t_rec, m = messages[pose]
        qx, qy, qz, qw = m[:, 4], m[:, 5], m[:, 6], m[:, 7]
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        p = np.column_stack([m[:, 0], t_rec, m[:, 1], m[:, 2], yaw])
        if cmd in messages:
            t_cmd, tw = messages[cmd]
            c = np.column_stack([t_cmd, tw[:, 0], tw[:, 5]])
        else:
            c = np.zeros((0, 3))
        if np.all(p[:, 0] == 0.0):
            warn("%s: robot %s: pose header stamps are all zero; using the record time" % (path, name))
            p[:, 0] = p[:, 1]
        p = p[np.argsort(p[:, 0], kind="stable")]
        dup = np.concatenate([np.diff(p[:, 0]) > 0, [True]])   # a repeated stamp: keep the last sample
        if not np.all(dup):
            warn("%s: robot %s: %d pose samples with a repeated stamp dropped" % (path, name, int((~dup).sum())))
        p = p[dup]
        out.append((name, p, c))
    return _dataset(path, out)


def _dataset(path, items, unknown=None, kind="bag", exact=True):
    """items: (name, poses (t, _, x, y, yaw), commands (t, v, w)) with absolute times;
    unknown: name -> (k, 2) intervals of unknown command timing."""
    starts = [p[0, 0] for _, p, _ in items] + [c[0, 0] for _, _, c in items if c.shape[0]]
    t0 = float(min(starts))
    robots = []
    for name, p, c in items:
        order = np.argsort(c[:, 0], kind="stable")
        c = c[order]
        gaps = (unknown or {}).get(name, np.zeros((0, 2))) - t0
        robots.append(RobotData(name=name, t=p[:, 0] - t0, x=p[:, 2], y=p[:, 3], yaw=p[:, 4],
                                cmd_t=c[:, 0] - t0, cmd_v=c[:, 1], cmd_w=c[:, 2], cmd_unknown=gaps,
                                t_start=float(p[0, 0] - t0) if p.shape[0] else 0.0))
    return Dataset(path=path, robots=robots, t0=t0, kind=kind, exact_command_times=exact)


# ----------------------------------------------------------------------- csv
def read_csv(path, robots=None):
    """CSV rows -> per-robot poses and command events.

    The command in force on a row was issued at the row's ``t_cmd`` if the file
    has that column (exact, like a bag). Without it, the documented convention:
    a command seen first on a row is taken as issued midway between that row and
    the robot's previous row (the row only says it was in force by then; right
    on average for commands issued independently of the pose rows, half a pose
    period early for commands logged on the pose rows). An empty v_cmd/w_cmd
    cell means no command known yet.
    """
    with open(path, newline="") as f:
        reader = csv.reader(f)
        try:
            header = next(reader)
        except StopIteration:
            raise DataError("%s: empty file (expected the CSV header %s)" % (path, ",".join(CSV_COLUMNS))) from None
        except csv.Error as e:
            raise DataError("%s: not a readable CSV file: %s" % (path, e)) from None
        header = [h.strip() for h in header]
        missing = [c for c in CSV_COLUMNS if c not in header]
        if missing:
            raise DataError("%s: missing CSV column(s) %s (header: %s; expected %s)"
                            % (path, ", ".join(missing), ",".join(header), ",".join(CSV_COLUMNS)))
        numeric = ["t", "x", "y", "yaw", "v_cmd", "w_cmd"] + ([CSV_COMMAND_TIME] if CSV_COMMAND_TIME in header else [])
        col = {c: header.index(c) for c in list(CSV_COLUMNS) + numeric}
        optional = ("v_cmd", "w_cmd", CSV_COMMAND_TIME)
        rows = {}
        try:
            for line_no, row in enumerate(reader, start=2):
                if not row or all(not cell.strip() for cell in row):
                    continue
                if len(row) < len(header):
                    raise DataError("%s: line %d: %d fields, the header has %d" % (path, line_no, len(row), len(header)))
                vals = []
                for c in numeric:
                    cell = row[col[c]].strip()
                    if cell == "" and c in optional:
                        vals.append(math.nan)
                        continue
                    try:
                        value = float(cell)
                    except ValueError:
                        raise DataError("%s: line %d: column %s: not a number: %r" % (path, line_no, c, cell)) from None
                    if not math.isfinite(value):
                        raise DataError("%s: line %d: column %s: not a finite number: %r" % (path, line_no, c, cell))
                    vals.append(value)
                rows.setdefault(row[col["robot"]].strip(), []).append([line_no] + vals)
        except csv.Error as e:
            raise DataError("%s: not a readable CSV file: %s" % (path, e)) from None
    if not rows:
        raise DataError("%s: no data rows after the header" % path)
    if robots:
        chosen = []
        for spec in robots:
            if spec.name not in rows:
                raise DataError("%s: robot %s has no rows (robots in the file: %s)"
                                % (path, spec.name, ", ".join(sorted(rows))))
            chosen.append(spec.name)
    else:
        chosen = sorted(rows)
    with_time = CSV_COMMAND_TIME in header
    items, unknown = [], {}
    for name in chosen:
        a = np.array(rows[name], dtype=float)
        back = np.nonzero(np.diff(a[:, 1]) <= 0)[0]
        if back.size:
            i = int(back[0])
            raise DataError("%s: robot %s: time is not increasing at line %d (t=%s after t=%s on line %d)"
                            % (path, name, a[i + 1, 0], repr(a[i + 1, 1]), repr(a[i, 1]), a[i, 0]))
        has_cmd = np.isfinite(a[:, 5]) & np.isfinite(a[:, 6])
        if not np.any(has_cmd):
            raise DataError("%s: robot %s has no commands (v_cmd, w_cmd empty on every row)" % (path, name))
        t, cv, cw = a[:, 1], a[:, 5], a[:, 6]
        if with_time:
            events = _csv_timed_events(path, name, a, has_cmd)
        else:
            events = _csv_events(t, cv, cw, has_cmd)
        period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        gaps, prev = [], None
        for i in np.nonzero(has_cmd)[0]:
            cmd = (cv[i], cw[i]) if not with_time else a[i, 7]
            if prev is not None and cmd != prev and i > 0 and t[i] - t[i - 1] > CSV_GAP_PERIODS * period:
                gaps.append((t[i - 1], t[i]))
            prev = cmd
        poses = np.column_stack([t, t, a[:, 2], a[:, 3], a[:, 4]])
        items.append((name, poses, np.array(events, dtype=float).reshape(-1, 3)))
        unknown[name] = np.array(gaps, dtype=float).reshape(-1, 2)
    return _dataset(path, items, unknown, kind="csv", exact=with_time)


def _csv_events(t, cv, cw, has_cmd):
    """Command events (t_issue, v, w) by the convention: issued midway between the row where a
    command first appears and the row before."""
    events, prev = [], None
    for i in np.nonzero(has_cmd)[0]:
        cmd = (cv[i], cw[i])
        if cmd != prev:
            t_issue = t[i] if (prev is None or i == 0) else 0.5 * (t[i - 1] + t[i])
            events.append((t_issue, cmd[0], cmd[1]))
            prev = cmd
    return events


def _csv_timed_events(path, name, a, has_cmd):
    """Command events from the t_cmd column: one per distinct issue time, checked (issued at or
    before its row, never earlier than the previous command)."""
    events, prev = [], None
    for i in np.nonzero(has_cmd)[0]:
        line, t, tc = int(a[i, 0]), a[i, 1], a[i, 7]
        if not math.isfinite(tc):
            raise DataError("%s: line %d: robot %s: a command without its %s" % (path, line, name, CSV_COMMAND_TIME))
        if tc > t + 1e-9:
            raise DataError("%s: line %d: robot %s: %s=%r is after the row's t=%r (the command in force on a "
                            "row was issued at or before it)" % (path, line, name, CSV_COMMAND_TIME, tc, t))
        if prev is not None and tc < prev - 1e-9:
            raise DataError("%s: line %d: robot %s: %s goes backwards (%r after %r)"
                            % (path, line, name, CSV_COMMAND_TIME, tc, prev))
        if prev is None or tc > prev + 1e-9:
            events.append((tc, a[i, 5], a[i, 6]))
            prev = tc
    return events


# -------------------------------------------------------------- mocap glitches
GLITCH_WINDOW = 5    # samples of the running median a pose is compared with


def drop_glitches(dataset, settings):
    """Drop pose samples that jump away from their neighbours (marker swaps, reflections).

    For each sample, the median over the GLITCH_WINDOW samples around it (itself
    included) of its distance to them, in position and in wrapped yaw: a lone
    glitch, or two in a row, is far from most of its window, a good sample next to
    them is not. A sample is dropped when that median exceeds what the robot could
    move in half the window's time span at ``glitch_speed`` (``glitch_turn_rate``)
    plus a margin. Returns warnings (one per robot with glitches)."""
    warnings = []
    half = GLITCH_WINDOW // 2
    for r in dataset.robots:
        if r.t.size < GLITCH_WINDOW:
            continue
        idx = sliding_window_view(np.arange(r.t.size), GLITCH_WINDOW)    # windows, centre = idx[:, half]
        centre = idx[:, half:half + 1]
        span = 0.5 * (r.t[idx[:, -1]] - r.t[idx[:, 0]])
        dist = np.hypot(r.x[idx] - r.x[centre], r.y[idx] - r.y[centre])
        turn = np.abs(wrap_angle(r.yaw[idx] - r.yaw[centre]))
        bad = np.zeros(r.t.size, bool)
        bad[half:-half] = ((np.median(dist, axis=1) > settings.glitch_speed * span + settings.glitch_margin_m)
                           | (np.median(turn, axis=1) > settings.glitch_turn_rate * span
                              + settings.glitch_margin_rad))
        if bad.any():
            first = float(r.t[bad][0])
            keep = ~bad
            r.t, r.x, r.y, r.yaw = r.t[keep], r.x[keep], r.y[keep], r.yaw[keep]
            warnings.append("robot %s: %d pose sample(s) jumping away from their neighbours dropped as mocap "
                            "glitches (first at t=%.2f s from the start of the data)" % (r.name, int(bad.sum()), first))
    return warnings
