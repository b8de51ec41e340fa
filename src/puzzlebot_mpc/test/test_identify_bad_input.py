"""Bad input to identify_model: one clear line naming the problem, exit status 2, no traceback."""

import os
import subprocess
import sys

import pytest

import identify_synth as synth
from puzzlebot_mpc.identify.cli import main

HEADER = "t,robot,x,y,yaw,v_cmd,w_cmd\n"


def csv_rows(n=400, dt=0.01, robot="pz1", v=0.05, w=0.3):
    """A short valid CSV body: one robot driving an arc."""
    return "".join("%.3f,%s,%.5f,0.0,%.4f,%s,%s\n" % (k * dt, robot, v * k * dt, w * k * dt, v, w) for k in range(n))


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def bag_with(tmp_path, name, robots=("pz1",), cmd_robots=None, zero_commands=False, duration=6.0):
    rec = synth.lab_record({}, n_robots=len(robots), duration=duration, seed=5)
    rec = {new: r for new, r in zip(robots, rec.values())}
    if zero_commands:
        for r in rec.values():
            r["cmd"] = [(t, 0.0, 0.0) for t, _, _ in r["cmd"]]
    path = str(tmp_path / name)
    synth.write_bag(path, rec, cmd_robots=cmd_robots)
    return path


def run_cli(capsys, args):
    code = main(args)
    captured = capsys.readouterr()
    return code, captured.err


def empty_bag(tmp_path):
    import rosbag

    path = str(tmp_path / "nomsg.bag")
    rosbag.Bag(path, "w").close()
    return path


def chatter_bag(tmp_path):
    import rosbag
    from std_msgs.msg import String

    path = str(tmp_path / "chatter.bag")
    with rosbag.Bag(path, "w") as bag:
        import rospy

        bag.write("/chatter", String(data="hello"), rospy.Time(1.0))
    return path


CASES = {
    "missing file": (lambda p: str(p / "nope.bag"), "no such file"),
    "unknown format": (lambda p: write(p, "data.txt", "x"), "unknown data format"),
    "zero-byte bag": (lambda p: write(p, "zero.bag", ""), "empty file"),
    "bag without messages": (empty_bag, "empty bag"),
    "bag without the topics": (chatter_bag, "no pose topics /vicon/<robot>/<robot>"),
    "robot with poses but no cmd_vel": (lambda p: bag_with(p, "nocmd.bag", ("pz1", "pz2"), cmd_robots=["pz1"]),
                                        "robot pz2 has poses"),
    "robot with only zero commands": (lambda p: bag_with(p, "zero_cmd.bag", zero_commands=True),
                                      "robot pz1 has no commands"),
    "csv empty": (lambda p: write(p, "empty.csv", ""), "empty file"),
    "csv missing columns": (lambda p: write(p, "cols.csv", "t,robot,x,y,yaw\n0,pz1,0,0,0\n"),
                            "missing CSV column(s) v_cmd, w_cmd"),
    "csv time not increasing": (lambda p: write(p, "back.csv", HEADER + "0.00,pz1,0,0,0,0.1,0\n0.02,pz1,0,0,0,0.1,0\n"
                                                "0.01,pz1,0,0,0,0.1,0\n"), "time is not increasing at line 4"),
    "csv repeated time": (lambda p: write(p, "dup.csv", HEADER + "0.00,pz1,0,0,0,0.1,0\n0.00,pz1,0,0,0,0.1,0\n"),
                          "time is not increasing"),
    "csv not a number": (lambda p: write(p, "nan.csv", HEADER + "0.0,pz1,abc,0,0,0.1,0\n"),
                         "line 2: column x: not a number"),
    "csv robot without commands": (lambda p: write(p, "nocmd.csv", HEADER + "0.0,pz1,0,0,0,,\n0.01,pz1,0,0,0,,\n"),
                                   "robot pz1 has no commands"),
    "csv only a header": (lambda p: write(p, "header.csv", HEADER), "no data rows"),
    "csv too short": (lambda p: write(p, "short.csv", HEADER + csv_rows(150)), "too short"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_data_is_one_clear_line(tmp_path, capsys, case):
    make, fragment = CASES[case]
    code, err = run_cli(capsys, [make(tmp_path), "--quiet"])
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("identify_model: error:"), err
    assert fragment in lines[0], lines[0]


def test_bad_options(tmp_path, capsys):
    data = write(tmp_path, "ok.csv", HEADER + csv_rows(1500))
    bad_cfg = write(tmp_path, "cfg.yaml", "identify:\n  horizon: 2.0\n")
    code, err = run_cli(capsys, [data, "--config", bad_cfg, "--quiet"])
    assert code == 2 and "unknown key(s) horizon" in err and "Traceback" not in err
    code, err = run_cli(capsys, [data, "--robots", "pz9", "--quiet"])
    assert code == 2 and "robot pz9 has no rows" in err
    code, err = run_cli(capsys, [data, "--out", str(tmp_path / "no" / "dir" / "r.json"), "--quiet"])
    assert code == 2 and "cannot write the report" in err


def test_node_script_exit_status_without_traceback(tmp_path):
    """The installed entry point (as rosrun runs it) on a bag without the topics."""
    node = os.path.join(os.path.dirname(__file__), "..", "nodes", "identify_model")
    proc = subprocess.run([sys.executable, node, chatter_bag(tmp_path), "--out", str(tmp_path / "r.json")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "no pose topics" in proc.stderr
    assert not (tmp_path / "r.json").exists()


def test_robot_selection_with_a_robot_list(tmp_path, capsys):
    """A vicon subject without commands is an error unless --robots leaves it out."""
    path = bag_with(tmp_path, "sel.bag", ("pz1", "pz2"), cmd_robots=["pz1"], duration=20.0)
    rl = write(tmp_path, "robots.yaml", "robots:\n  - name: pz1\n")
    code = main([path, "--robots", rl, "--quiet"])
    out = capsys.readouterr().out
    assert code == 0
    assert "robots: pz1;" in out
