"""Run one seeded trial across model variants: is a result robust to what is not measured?

A variant is a name and overrides of RobotParams / AnchorParams fields (e.g. a
ground clearance or a body friction the sources do not give). The variants
come from a YAML file (config/variants.yaml)::

    variants:
      default: {}
      clearance_5mm: {robot: {ground_clearance: 0.005}}

Every variant runs the same trial on the same seeds; ``table`` prints one row
per variant and a total. ROS-free; used by ``anchor_trials --variants``.

The model every variant starts from is a robot file read by
puzzlebot_sim.config.load_model (default: the sim's config/robot.yaml, the
file the sim node and the experiments load) with command-line overrides on top.
"""


from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_common.params import key_values
from puzzlebot_sim.config import load_model, override
from puzzlebot_sim.params import AnchorParams, RobotParams
from puzzlebot_experiments.trials import summarize


def add_model_options(parser):
    """Add the options that choose the model to an argparse parser: --robot-file, --robot, --anchor."""
    parser.add_argument("--robot-file", default=None, metavar="FILE",
                        help="robot file with the keys robot and anchor (default: the package's config/robot.yaml)")
    parser.add_argument("--robot", action="append", default=[], metavar="KEY=VALUE",
                        help="override a RobotParams field (repeatable), e.g. ground_clearance=0.005")
    parser.add_argument("--anchor", action="append", default=[], metavar="KEY=VALUE",
                        help="override an AnchorParams field (repeatable), e.g. keel_height=0.0075")


def model_from_options(args):
    """(RobotParams, AnchorParams) from the options of ``add_model_options``."""
    return load_model(args.robot_file, key_values(args.robot, "--robot"), key_values(args.anchor, "--anchor"))


def load_variants(path, robot=RobotParams(), anchor=AnchorParams()):
    """[(name, RobotParams, AnchorParams)] from a variants file, each on top of ``robot`` / ``anchor``.

    Unknown keys, wrong types and parameter sets that fail their checks raise
    ConfigError naming the file and the variant.
    """
    data = load_yaml(path)
    variants = data.get("variants") if isinstance(data, dict) else None
    if not isinstance(variants, dict) or not variants:
        raise ConfigError("%s: expected a non-empty mapping 'variants: {name: {robot: {...}, anchor: {...}}}'"
                          % path)
    out = []
    for name, spec in variants.items():
        where = "%s: variants.%s" % (path, name)
        spec = {} if spec is None else spec
        if not isinstance(spec, dict) or set(spec) - {"robot", "anchor"}:
            raise ConfigError("%s: expected a mapping with the keys robot and/or anchor, got %r" % (where, spec))
        r = override(robot, spec.get("robot"), where + ".robot")
        a = override(anchor, spec.get("anchor"), where + ".anchor")
        a.check_fits(r, where=where)
        out.append((str(name), r, a))
    return out


def run_job(job):
    """(variant name, result) of one job (variant name, trial function of the seed, seed); picklable."""
    name, trial, seed = job
    return name, trial(seed)


def table(rows):
    """Text table: one row per (variant name, [trial result dicts]) and a total.

    Columns: successes / trials, failures with a pair that came apart
    (``pairs_ever_decoupled``, chain trials), other failures, and the mean
    time of the successes [s].
    """
    lines = ["%-24s %9s %10s %7s %8s" % ("variant", "success", "separated", "other", "mean_s")]
    total_ok = total = 0
    for name, results in rows:
        s = summarize(results)
        apart = sum(1 for r in results if not r["success"] and r.get("pairs_ever_decoupled"))
        lines.append("%-24s %9s %10d %7d %8s" % (
            name, "%d/%d" % (s["successes"], s["trials"]), apart, s["trials"] - s["successes"] - apart,
            "-" if s["mean_time_s"] is None else "%.2f" % s["mean_time_s"]))
        total_ok += s["successes"]
        total += s["trials"]
    lines.append("%-24s %9s" % ("all", "%d/%d" % (total_ok, total)))
    return "\n".join(lines)
