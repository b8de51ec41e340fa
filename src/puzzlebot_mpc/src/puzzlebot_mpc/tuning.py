"""Live tuning of the MPC's weights and limits (dynamic_reconfigure), without ROS.

The MPC node serves dynamic_reconfigure at ``~tuning`` (``/mpc/tuning``
in the launch files; tuning_server.py). Its parameters are the
MPCSettings fields of :data:`TUNABLE`, described from settings.py (type,
the comment beside each field), starting at the node's settings (the YAML).
A change is validated exactly as the YAML is (``MPCSettings.from_dict``:
types, ranges, cross-field checks such as v_max <= hardware_v_max); a
refused change leaves every value as it was and the reason is the
parameter ``refused`` of the answer (and the node's log). An accepted one
is used from the next control step:

- ``goal_tolerance`` is read by go_to_goal every step, ``edges`` and
  ``edge_margin`` by the control loop's edge boxes (level LIVE);
- the weights and limits are constants of the MPC's CasADi problem
  (ocp.py), so a change of any of them (level REBUILD) builds the problem
  anew for the current pair structure, in the reconfigure thread while the
  controller runs on with the old one, and the new one takes over at the
  next control step after it is built (its first solve is a cold start).
"""

import inspect
import math
import re
from dataclasses import asdict, fields
from types import SimpleNamespace

from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.settings import MPCSettings

#: dynamic_reconfigure levels (bits): what a change needs before it is used
LIVE, REBUILD = 1, 2
#: the tunable MPCSettings fields and their level
TUNABLE = {name: REBUILD for name in (
    "v_max", "w_max", "dv_max", "dw_max", "butterfly", "w_free",
    "w_goal_terminal", "w_goal_stage", "w_goal_lateral", "w_velocity", "w_rest", "w_control",
    "w_pair_terminal_pos", "w_pair_terminal_angle", "w_pair_stage_pos", "w_pair_stage_angle", "w_pair_lateral",
    "w_coupled_pos", "w_coupled_angle", "w_slack_pip", "w_slack_butterfly", "w_slack_edge", "slack_regularisation", "pip_margin")}
TUNABLE.update(goal_tolerance=LIVE, edges=LIVE, edge_margin=LIVE)
#: the answer's parameter that says why the last change was refused ("" when it was applied)
REFUSED = "refused"


def _comments():
    """MPCSettings field -> the comment beside it in settings.py (its unit and meaning)."""
    out, current = {}, None
    for line in inspect.getsource(MPCSettings).splitlines():
        m = re.match(r"\s+(\w+): \w+ = [^#]*#\s*(.*)", line)
        if m:
            current = m.group(1)
            out[current] = m.group(2).strip()
        elif current and re.match(r"\s+#\s*(.*)", line) and not re.match(r"\s+\w+:", line):
            out[current] += " " + re.match(r"\s+#\s*(.*)", line).group(1).strip()
        else:
            current = None
    return out


def config_type(settings):
    """The dynamic_reconfigure description of :data:`TUNABLE` with ``settings`` as the defaults: an object
    like the module ``dynamic_reconfigure.parameter_generator`` generates (config_description, defaults,
    min, max, level, type, all_level). No min / max: out-of-range values reach the check (and are refused
    with its reason) instead of being clamped silently."""
    comments = _comments()
    kinds = {f.name: f.type for f in fields(MPCSettings)}
    params = []
    for name, level in TUNABLE.items():
        kind = {bool: "bool", int: "int", float: "double"}[kinds[name]]
        lo, hi = {"bool": (False, True), "int": (-2 ** 31, 2 ** 31 - 1), "double": (-math.inf, math.inf)}[kind]
        params.append({"name": name, "type": kind, "default": getattr(settings, name), "level": level,
                       "description": comments.get(name, ""), "min": lo, "max": hi, "edit_method": "",
                       "srcline": 0, "srcfile": "puzzlebot_mpc/settings.py", "ctype": kind,
                       "cconsttype": "const " + kind})
    params.append({"name": REFUSED, "type": "str", "default": "", "level": 0,
                   "description": "read-only: why the last change was refused ('' = applied)", "min": "", "max": "",
                   "edit_method": "", "srcline": 0, "srcfile": "puzzlebot_mpc/tuning.py", "ctype": "std::string",
                   "cconsttype": "const char * const"})
    description = {"name": "Default", "type": "", "state": True, "cstate": "true", "id": 0, "parent": 0,
                   "parameters": params, "groups": [], "srcline": 0, "srcfile": "puzzlebot_mpc/tuning.py",
                   "class": "DEFAULT", "parentclass": "", "parentname": "Default", "field": "default",
                   "upper": "DEFAULT", "lower": "groups"}
    out = SimpleNamespace(config_description=description, min={}, max={}, defaults={}, level={}, type={},
                          all_level=0)
    for p in params:
        out.min[p["name"]], out.max[p["name"]] = p["min"], p["max"]
        out.defaults[p["name"]], out.level[p["name"]] = p["default"], p["level"]
        out.type[p["name"]] = p["type"]
        out.all_level |= p["level"]
    return out


def changes(settings, config):
    """{field: new value} of the tunable fields whose value in ``config`` (a dynamic_reconfigure
    config: name -> value) differs from ``settings``."""
    return {k: config[k] for k in TUNABLE if k in config and config[k] != getattr(settings, k)}


def tuned(settings, config, where="~tuning"):
    """(new MPCSettings, changed fields, needs a rebuild) for ``config``, validated as the YAML is;
    ConfigError (the reason) if the new values are refused."""
    diff = changes(settings, config)
    if not diff:
        return settings, {}, False
    data = asdict(settings)
    data.update(diff)
    new = MPCSettings.from_dict(data, where=where)           # types, ranges, cross-field checks
    return new, diff, any(TUNABLE[k] & REBUILD for k in diff)


def describe(diff, settings):
    """'w_max 1.5 -> 1.0, ...' of a change."""
    return ", ".join("%s %s -> %s" % (k, getattr(settings, k), v) for k, v in sorted(diff.items()))


__all__ = ["LIVE", "REBUILD", "REFUSED", "TUNABLE", "ConfigError", "changes", "config_type", "describe", "tuned"]
