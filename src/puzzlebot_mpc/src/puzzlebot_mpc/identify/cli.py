"""Command line of the model-identification tool (``rosrun puzzlebot_mpc identify_model``,
``python -m puzzlebot_mpc.identify``). No roscore needed.

    identify_model DATA [--out report.json] [--model-out model.yaml] [--plot residuals.png]
                   [--robots pz1,pz2 | --robots robots.yaml] [--config identify.yaml] [--quiet]

Exit status: 0 done; 2 unusable input or options (one line on stderr naming
the problem); 1 internal error (one line; ``--debug`` shows the traceback).
"""

import argparse
import json
import os
import sys

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list
from puzzlebot_mpc.identify.data import DataError
from puzzlebot_mpc.identify.settings import IdentifySettings

PROG = "identify_model"


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        self.print_usage(sys.stderr)
        print("%s: error: %s" % (PROG, message), file=sys.stderr)
        sys.exit(2)


def parse_args(argv):
    p = _Parser(prog=PROG, description="Identify the actuator effects a PuzzleBot's plain unicycle model lacks "
                "from measured data, and report the open-loop prediction error before and after.")
    p.add_argument("data", metavar="DATA", help="ROS 1 bag (/vicon/<r>/<r>, /<r>/cmd_vel) or CSV "
                   "(t,robot,x,y,yaw,v_cmd,w_cmd)")
    p.add_argument("--out", metavar="report.json", help="write the report as JSON")
    p.add_argument("--model-out", metavar="model.yaml", help="write the identified model (puzzlebot_common.effects)")
    p.add_argument("--plot", metavar="residuals.png", help="write the residual plots")
    p.add_argument("--robots", metavar="LIST", help="robots to use: comma-separated names, or a robot-list YAML "
                   "file (its mocap subjects name the pose topics); default: every /vicon/<r>/<r> in the data")
    p.add_argument("--config", metavar="identify.yaml", help="settings overriding the defaults "
                   "(config/identify.yaml shows them)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument("--debug", action="store_true", help="show the traceback of an internal error")
    # roslaunch/rosrun may append remappings such as __name:=...; they mean nothing here.
    return p.parse_args([a for a in argv if not (a.startswith("__") and ":=" in a)])


def _robots(arg):
    if arg is None:
        return None
    if os.path.isfile(arg):
        return parse_robot_list(load_yaml(arg), where=arg)
    return parse_robot_list([n.strip() for n in arg.split(",") if n.strip()], where="--robots")


def _write(path, what, writer):
    try:
        writer(path)
    except OSError as e:
        raise DataError("cannot write the %s to %s: %s" % (what, path, e.strerror or e)) from None


def one_blas_thread():
    """Run the BLAS libraries numpy and scipy loaded on one thread, unless the user chose a number
    (OPENBLAS_NUM_THREADS, OMP_NUM_THREADS). The tool's matrices are small (a few parameters x a
    few thousand windows): a second BLAS thread does not make it faster, it spins between the
    calls and takes a core from the main thread (on two cores: up to twice the CPU time, and
    more wall time on a loaded machine). The results do not change. Returns the libraries set
    (threadpoolctl's descriptions)."""
    if "OPENBLAS_NUM_THREADS" in os.environ or "OMP_NUM_THREADS" in os.environ:
        return []
    import scipy.linalg  # noqa: F401  (scipy's own BLAS is loaded with it: set both)
    from threadpoolctl import threadpool_info, threadpool_limits

    threadpool_limits(1, user_api="blas")
    return [i for i in threadpool_info() if i["user_api"] == "blas"]


def run(args):
    from puzzlebot_mpc.identify import core, report

    one_blas_thread()
    settings = IdentifySettings.from_dict(load_yaml(args.config), where=args.config) if args.config \
        else IdentifySettings()
    progress = None if args.quiet else (lambda msg: print("%s: %s" % (PROG, msg), file=sys.stderr, flush=True))
    result = core.identify(args.data, settings, _robots(args.robots), progress)
    rep = report.report_dict(result)
    if args.out:
        def dump(path):
            with open(path, "w") as f:
                json.dump(rep, f, indent=1)
                f.write("\n")
        _write(args.out, "report", dump)
    if args.model_out:
        _write(args.model_out, "model", result.model.dump)
    if args.plot:
        from puzzlebot_mpc.identify import plots

        _write(args.plot, "plot", lambda path: plots.plot(result, path))
    print(report.table(result))
    return result


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        run(args)
    except (DataError, ConfigError) as e:
        print("%s: error: %s" % (PROG, e), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("%s: interrupted" % PROG, file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - one line instead of a traceback, unless --debug
        if args.debug:
            raise
        print("%s: internal error: %s: %s (rerun with --debug for the traceback)"
              % (PROG, type(e).__name__, e), file=sys.stderr)
        return 1
    return 0
