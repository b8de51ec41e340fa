"""The fast bag reader (identify/bagfile.py) gives what rosbag gives, for plain, bz2 and unindexed bags."""

import numpy as np
import pytest

import identify_synth as synth
from puzzlebot_mpc.identify import bagfile, data

rosbag = pytest.importorskip("rosbag")


def reference(path):
    """{topic: (record times, rows)} by rosbag, in the reader's column order."""
    out = {}
    with rosbag.Bag(path) as bag:
        for topic, m, t in bag.read_messages():
            if "vicon" in topic:
                tr, q = m.transform.translation, m.transform.rotation
                row = (m.header.stamp.to_sec(), tr.x, tr.y, tr.z, q.x, q.y, q.z, q.w)
            else:
                row = (m.linear.x, m.linear.y, m.linear.z, m.angular.x, m.angular.y, m.angular.z)
            out.setdefault(topic, ([], []))
            out[topic][0].append(t.to_sec())
            out[topic][1].append(row)
    return {k: (np.array(a), np.array(b)) for k, (a, b) in out.items()}


def strip_index(src, dst):
    """A copy of a bag without its index records and index section (as a bag that was never closed)."""
    raw = open(src, "rb").read()
    kept = [raw[:len(bagfile.MAGIC)]]
    for hdr, start, dstart, dlen in bagfile._records(memoryview(raw), len(bagfile.MAGIC), len(raw)):
        if bagfile._op(hdr) in (bagfile.OP_CHUNK, bagfile.OP_BAG_HEADER):
            kept.append(raw[start:dstart + dlen])
    open(dst, "wb").write(b"".join(kept))


@pytest.mark.parametrize("kind", ["plain", "bz2", "unindexed"])
def test_reader_matches_rosbag(tmp_path, kind):
    rec = synth.lab_record({}, n_robots=2, duration=8.0, seed=3)
    path = str(tmp_path / "run.bag")
    if kind == "bz2":
        import rospy
        from geometry_msgs.msg import Twist

        with rosbag.Bag(path, "w", compression="bz2") as bag:
            for k, (t, v, w) in enumerate(rec["pz1"]["cmd"]):
                m = Twist()
                m.linear.x, m.angular.z = v, w
                bag.write("/pz1/cmd_vel", m, rospy.Time.from_sec(1000.0 + t))
    else:
        synth.write_bag(path, rec)
    ref = reference(path)
    if kind == "unindexed":
        stripped = str(tmp_path / "unindexed.bag")
        strip_index(path, stripped)
        path = stripped
    info, messages = bagfile.read(path, set(ref))
    assert set(messages) == set(ref)
    for topic, (t, rows) in ref.items():
        assert info[topic][1] == t.size
        np.testing.assert_array_equal(messages[topic][0], t)
        np.testing.assert_array_equal(messages[topic][1], rows)


def test_not_a_bag_and_truncated_bags_are_clear_errors(tmp_path):
    bad = tmp_path / "text.bag"
    bad.write_text("hello, not a bag\n")
    with pytest.raises(data.DataError, match="not a readable ROS bag: not a ROS 1 bag"):
        data.load(str(bad))
    rec = synth.lab_record({}, n_robots=1, duration=4.0, seed=4)
    path = tmp_path / "run.bag"
    synth.write_bag(str(path), rec)
    raw = path.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(raw[:len(raw) // 2])
    with pytest.raises(data.DataError, match="truncated"):
        data.load(str(cut))
