import math
from dataclasses import replace

import numpy as np
import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_sim.anchor import AnchorGeometry, BarbTorqueMap
from puzzlebot_sim.coupling import (DECOUPLED, HEAD_ALIGNED, HEAD_INSERTED, classify, classify_knob, knob_reason,
                                    unseated_reason)
from puzzlebot_sim.params import AnchorParams, RobotParams


def tmap(a=AnchorParams(), p=RobotParams()):
    return BarbTorqueMap(a, p.mouth_width, p.lip_depth / 2)


def test_torque_law_is_asymmetric_and_snaps_through_at_the_end_of_the_profile():
    a, m = AnchorParams(), tmap()
    assert m.torque_at(0.0) == pytest.approx(a.barb_min_torque, rel=0.1)       # at rest: only the floor
    # backward (flare): torque = F(d)/2 * b sin(phi); e.g. at d = 4 mm the anchor carries 0.6 N
    phi = math.acos(math.cos(a.barb_angle) - 0.004 / a.barb_length)
    tau = m.torque_at(phi - a.barb_angle)
    assert tau == pytest.approx(0.5 * 0.60 * a.barb_length * math.sin(phi), rel=0.02)
    assert m.backward_displacement(phi - a.barb_angle) == pytest.approx(0.004)
    # past the profile's end (5 mm) the beam snaps through and keeps barb_post_snap_ratio of its torque
    assert m.snap_mm == pytest.approx(5.0, abs=0.05)
    q_end = m.snap_angle - a.barb_angle
    assert 0.0 < a.barb_post_snap_ratio < 1.0
    for q in (q_end + 0.01, a.barb_flip_limit - a.barb_angle):
        assert m.torque_at(q) == pytest.approx(a.barb_post_snap_ratio * m.torque_at(q_end), rel=0.01)
        assert m.max_torque(q) == pytest.approx(m.torque_at(q))
    # ratio 0: the rig's snap-through, down to the floor
    assert tmap(replace(a, barb_post_snap_ratio=0.0)).torque_at(q_end + 0.01) == a.barb_min_torque
    for bad in (-0.1, 1.5):                                   # a share of the peak: 0..1
        with pytest.raises(ConfigError, match="barb_post_snap_ratio"):
            AnchorParams.from_dict({"barb_post_snap_ratio": bad})
    # forward (fold) torque is bounded by the forward profile through the contact geometry; the
    # tips pass the lips after the profile's 5 mm
    assert m.forward_pass_mm > 5.0
    assert np.all(np.diff(m.q) > 0)
    assert m.max_torque(np.array([0.3, -0.2])) == pytest.approx([m.torque_at(0.3), m.torque_at(-0.2)])


def test_tips_rest_on_the_lips_flat_face_and_fold_through_the_mouth():
    a, p = AnchorParams(), RobotParams()
    g = AnchorGeometry(a)
    rest = g.tip_centre(a.barb_angle)[1]
    assert rest > p.mouth_width / 2 + p.lip_depth / 2 + 0.0005          # on the flat face, not the rounded end
    folded = g.tip_centre(a.barb_fold_limit)[1] + a.barb_tip_radius
    assert folded < p.mouth_width / 2                                  # folded barbs pass the mouth
    assert g.half_width() < p.slit_width / 2


def test_stiffer_profile_gives_proportionally_larger_torques():
    a = AnchorParams()
    stiff = replace(a, backward_profile_n=tuple(2 * f for f in a.backward_profile_n))
    q = 0.6
    assert tmap(stiff).torque_at(q) == pytest.approx(2 * tmap(a).torque_at(q), rel=1e-6)


def points(head, tips):
    return np.array(head), [np.array(t) for t in tips]


def test_classify_coupling_states():
    p = RobotParams()
    h = p.body_side / 2
    z = p.opening_z
    seated = ((h - 0.012, 0.0, z), [(h - 0.006, 0.006, z), (h - 0.006, -0.006, z)])
    assert classify(*points(*seated), p) == HEAD_INSERTED
    half_in = ((h - 0.005, 0.0, z), [(h + 0.001, 0.006, z), (h + 0.001, -0.006, z)])
    assert classify(*points(*half_in), p) == HEAD_ALIGNED
    one_out = ((h - 0.012, 0.0, z), [(h - 0.006, 0.002, z), (h - 0.006, -0.006, z)])  # tip in the mouth
    assert classify(*points(*one_out), p) == HEAD_ALIGNED
    outside = ((h + 0.003, 0.0, z), [(h + 0.01, 0.006, z), (h + 0.01, -0.006, z)])
    assert classify(*points(*outside), p) == DECOUPLED
    too_high = ((h - 0.012, 0.0, z + 0.02), [(h - 0.006, 0.006, z + 0.02), (h - 0.006, -0.006, z + 0.02)])
    assert classify(*points(*too_high), p) == DECOUPLED
    in_lock_slot = ((h - 0.012, 0.0, z + p.mouth_height / 2 + 0.003), seated[1])
    assert classify(*points(*in_lock_slot), p) == HEAD_INSERTED


def test_why_an_anchor_in_the_opening_is_not_seated():
    p = RobotParams()
    h, z = p.body_side / 2, p.opening_z
    head = (h - 0.012, 0.0, z)
    assert unseated_reason(*points(head, [(h - 0.006, 0.006, z), (h - 0.006, -0.006, z)]), p) == ""
    folded = unseated_reason(*points(head, [(h - 0.006, 0.0037, z), (h - 0.006, -0.0092, z)]), p)   # traced, line8
    assert folded.startswith("barb L folded into the mouth (3.7 mm off the axis") and "R" not in folded
    # with the tips' rounded ends: a tip 3.7 mm off the axis reaches behind the lip (4.25 mm), which catches it
    # when pulled (scenario_trials --pull-test: such pairs held like seated ones); tips 2.3 mm off do not
    r = AnchorParams().barb_tip_radius
    caught = points(head, [(h - 0.006, 0.0037, z), (h - 0.006, -0.0092, z)])
    assert unseated_reason(*caught, p, tip_radius=r) == "" and classify(*caught, p, tip_radius=r) == HEAD_INSERTED
    both = points(head, [(h - 0.006, -0.0023, z), (h - 0.006, -0.0023, z)])    # traced, line8: both folded
    assert unseated_reason(*both, p, tip_radius=r).count("R folded into the mouth (2.3 mm") == 2
    assert classify(*both, p, tip_radius=r) == HEAD_ALIGNED
    on_lip = unseated_reason(*points((h - 0.005, 0.0, z), [(h - 0.001, 0.006, z), (h - 0.006, -0.006, z)]), p)
    assert on_lip == "barb L on the lip"
    out = unseated_reason(*points((h - 0.005, 0.0, z), [(h + 0.004, 0.006, z), (h + 0.004, -0.006, z)]), p)
    assert out == "barb L outside the opening; barb R outside the opening"
    assert unseated_reason(*points((h + 0.003, 0.0, z), [(h + 0.01, 0.006, z)] * 2), p) == ""   # not in it


def test_classify_knob_states():
    p = RobotParams()
    face, z = -p.body_side / 2, p.knob_z           # the hole robot's right face; the knob's height
    assert classify_knob((0.0, face, z), p) == HEAD_INSERTED                 # sides touching, knob centred
    assert classify_knob((0.0005, face + 0.0005, z + 0.001), p) == HEAD_INSERTED
    assert classify_knob((0.0, face - 0.003, z), p) == HEAD_ALIGNED          # 3 mm gap: only the rim is in
    assert classify_knob((0.003, face, z), p) == HEAD_ALIGNED                # against the hole's edge
    assert classify_knob((0.0, face - 0.005, z), p) == DECOUPLED             # gap wider than the knob's reach
    assert classify_knob((0.015, face, z), p) == DECOUPLED                   # beside the hole
    assert classify_knob((0.0, face, z + 0.012), p) == DECOUPLED             # above it
    assert classify_knob((0.0, -face, z), p) == DECOUPLED                    # on the wrong side


def test_knob_reason_names_what_is_off():
    p = RobotParams()
    face, z = -p.body_side / 2, p.knob_z
    assert knob_reason((0.0, face, z), p) == ""                                    # seated
    assert knob_reason((0.015, face, z), p) == ""                                  # not at the hole
    assert knob_reason((0.0, face - 0.003, z), p) == "the knob partly in the hole: the sides 3.0 mm apart"
    edge = knob_reason((0.003, face, z), p)
    assert edge == "the knob partly in the hole: the knob 3.0 mm from the hole's centre along the side (play 0.5 mm)"
    both = knob_reason((-0.003, face - 0.002, z), p)
    assert both.startswith("the knob partly in the hole: the sides 2.0 mm apart; the knob 3.0 mm from")


def test_physical_knob_pairs_message():
    from puzzlebot_msgs.msg import ConnectionPair
    from puzzlebot_sim.coupling import PhysicalPair
    from puzzlebot_sim.ros_conversions import physical_pairs_msg

    msg = physical_pairs_msg([PhysicalPair("pz1", "pz2", HEAD_INSERTED),
                              PhysicalPair("pz3", "pz1", HEAD_ALIGNED, knob=True)], None, 0.05)
    anchor, knob = msg.pairs
    assert anchor.type == ConnectionPair.TYPE_ANCHOR and anchor.anchor_robot == "pz1"
    assert (anchor.point_i.x, anchor.point_j.x) == (-0.025, 0.025)
    assert knob.type == ConnectionPair.TYPE_KNOB and knob.anchor_robot == ""
    assert (knob.robot_i, knob.robot_j, knob.status) == ("pz3", "pz1", HEAD_ALIGNED)
    assert (knob.point_i.y, knob.point_j.y) == (0.025, -0.025)
