"""Physical coupling: which anchor sits in which opening, from the simulated bodies.

The status of an anchor-opening pair is read off the anchor linkage's actual
pose in the opening robot's frame (not off the robots' poses, as the MPC's
polygon model does):

* ``HEAD_INSERTED``: both barb tips are seated in the slits: behind the lips,
  inside the slit width and height, and not through the mouth: a tip's
  rounded end (``tip_radius``) reaches behind a lip, so a pull catches it
  there (a tip within the mouth's width draws out through it);
* ``HEAD_ALIGNED``: the head tip is inside the opening (behind the front
  face, within the slit width and height) but the tips are not both seated;
* ``DECOUPLED`` otherwise.

A knob-hole pair (side connection) is read off the knob robot's pose in the
hole robot's frame (:func:`classify_knob`): ``HEAD_INSERTED`` when the knob
sits in the hole (the two sides touch, the knob within the hole's width and
height), ``HEAD_ALIGNED`` when it is only partly in, ``DECOUPLED`` otherwise.

The numeric values match puzzlebot_msgs/ConnectionPair's STATUS_* constants.
"""

from dataclasses import dataclass

DECOUPLED = 0
HEAD_ALIGNED = 1
HEAD_INSERTED = 2

STATUS_NAMES = {DECOUPLED: "decoupled", HEAD_ALIGNED: "head_aligned", HEAD_INSERTED: "head_inserted"}


@dataclass(frozen=True)
class PhysicalPair:
    """An anchor in an opening: ``anchor_robot``'s anchor in ``opening_robot``'s front opening."""

    anchor_robot: str
    opening_robot: str
    status: int
    knob: bool = False     # a knob-hole pair: anchor_robot carries the knob, opening_robot has the hole
    reason: str = ""       # not seated: why (unseated_reason; knob_reason for a knob pair)

    @property
    def status_name(self):
        return STATUS_NAMES[self.status]


def _in_opening(p, rp, tolerance):
    """True when point ``p`` (opening robot's base_link) is inside the mouth/slit cavity
    (or up in the lock slot above it)."""
    h = rp.body_side / 2.0
    if not (h - rp.cavity_depth - tolerance <= p[0] < h and abs(p[1]) <= rp.slit_width / 2.0 + tolerance):
        return False
    dz = p[2] - rp.opening_z
    top = rp.mouth_height / 2.0
    if p[0] <= h - rp.lip_depth - rp.lock_sill and abs(p[1]) <= rp.lock_width / 2.0:
        top += rp.lock_height
    return -rp.mouth_height / 2.0 - tolerance <= dz <= top + tolerance


#: why a barb tip is not seated (unseated_reason's words)
BARB_FOLDED, BARB_ON_LIP, BARB_OUTSIDE = "folded into the mouth", "on the lip", "outside the opening"
KNOB_PARTLY = "the knob partly in the hole"   # a knob pair at its hole, not seated (knob_reason)


def _barb_fault(tip, rp, tolerance, tip_radius=0.0):
    """None when a barb tip's centre (opening robot's base_link [m]) is seated: in the slits, behind the
    lips, its rounded end (``tip_radius`` [m]) reaching behind a lip; else BARB_FOLDED, BARB_ON_LIP or
    BARB_OUTSIDE."""
    inside, behind = _in_opening(tip, rp, tolerance), tip[0] < rp.body_side / 2.0 - rp.lip_depth + tolerance
    if inside and behind:
        return None if abs(tip[1]) + tip_radius >= rp.mouth_width / 2.0 - tolerance else BARB_FOLDED
    if inside or (tip[0] < rp.body_side / 2.0 + tolerance and abs(tip[1]) <= rp.slit_width / 2.0 + tolerance):
        return BARB_ON_LIP
    return BARB_OUTSIDE


def classify(head_tip, barb_tips, rp, tolerance=0.0005, tip_radius=0.0):
    """Status of an anchor whose head tip and barb tip centres are given in the
    opening robot's base_link (x, y, z) [m]; ``rp``: that robot's RobotParams;
    ``tip_radius`` [m]: the barb tips' rounded ends (AnchorParams.barb_tip_radius).

    ``tolerance`` [m] absorbs contact penetration.
    """
    if not _in_opening(head_tip, rp, tolerance):
        return DECOUPLED
    seated = all(_barb_fault(t, rp, tolerance, tip_radius) is None for t in barb_tips)
    return HEAD_INSERTED if seated else HEAD_ALIGNED


def unseated_reason(head_tip, barb_tips, rp, tolerance=0.0005, tip_radius=0.0):
    """Why an anchor in an opening is not seated (classify's HEAD_ALIGNED): one short text per barb that is
    not, joined by "; " ("" when seated or not in the opening). Points as for :func:`classify`.

    - "barb L folded into the mouth": its tip behind the lips but so close to the axis that its rounded end
      (``tip_radius``) stays within the mouth's width (a pull draws it out through the mouth);
    - "barb L on the lip": its tip not behind the lips, but within the cavity's width;
    - "barb L outside the opening" otherwise (in front of the face, beside or above the slit).
    Barbs are named L (+y) and R (-y) by which side of the opening's axis their tip is on.
    """
    if not _in_opening(head_tip, rp, tolerance):
        return ""
    out = []
    for t in barb_tips:
        fault = _barb_fault(t, rp, tolerance, tip_radius)
        if fault is None:
            continue
        text = "barb %s %s" % ("L" if t[1] >= 0 else "R", fault)
        if fault == BARB_FOLDED:
            text += " (%.1f mm off the axis, the lips at %.1f mm)" % (1e3 * abs(t[1]), 1e3 * rp.mouth_width / 2.0)
        out.append(text)
    return "; ".join(out)


def classify_knob(knob_centre, rp, tolerance=0.001, depression=0.0):
    """Status of a knob whose centre (x, y, z) [m] is given in the hole robot's base_link.

    The hole is a pocket in the right side (y = -body_side/2) at height
    ``knob_z``; a knob of the neighbour on that side has its centre on the
    neighbour's left face, so with the two sides touching it lies on this
    robot's right face. ``tolerance`` [m] absorbs the gap between the sides
    and contact penetration. ``depression`` [m]: how far a sprung knob is
    pressed into its side (World.knob_depression): a knob pressed by more
    than ``tolerance`` sits on the hole's edge, not in it.
    """
    x, y, z = knob_centre
    gap = -rp.body_side / 2.0 - y                     # > 0: the knob robot's side is this far away
    dz = abs(z - rp.knob_z)
    if not -rp.hole_depth <= gap < rp.knob_radius or abs(x) >= rp.hole_width / 2.0 + rp.knob_radius \
            or dz >= (rp.hole_height + rp.knob_height) / 2.0:
        return DECOUPLED
    return HEAD_INSERTED if not _knob_faults(knob_centre, rp, tolerance, depression) else HEAD_ALIGNED


def _knob_faults(knob_centre, rp, tolerance, depression=0.0):
    """What keeps a knob that is at a hole (classify_knob not DECOUPLED) from being seated: a list of short
    texts, empty when it is seated. Points as for :func:`classify_knob`."""
    x, y, z = knob_centre
    gap = -rp.body_side / 2.0 - y
    play = rp.hole_width / 2.0 - rp.knob_radius
    out = []
    if gap > tolerance:
        out.append("the sides %.1f mm apart" % (1e3 * gap))
    if abs(x) > play + tolerance:
        out.append("the knob %.1f mm from the hole's centre along the side (play %.1f mm)" % (1e3 * abs(x), 1e3 * play))
    if abs(z - rp.knob_z) > (rp.hole_height - rp.knob_height) / 2.0 + tolerance:
        out.append("the knob %.1f mm off the hole's height" % (1e3 * abs(z - rp.knob_z)))
    if depression > tolerance:
        out.append("the knob pressed %.1f mm into its side" % (1e3 * depression))
    return out


def knob_reason(knob_centre, rp, tolerance=0.001, depression=0.0):
    """Why a knob at a hole is not seated (classify_knob's HEAD_ALIGNED): "the knob partly in the hole"
    and what is off, joined by "; " ("" when seated or not at the hole). Points as for :func:`classify_knob`."""
    if classify_knob(knob_centre, rp, tolerance, depression) != HEAD_ALIGNED:
        return ""
    return "%s: %s" % (KNOB_PARTLY, "; ".join(_knob_faults(knob_centre, rp, tolerance, depression)))
