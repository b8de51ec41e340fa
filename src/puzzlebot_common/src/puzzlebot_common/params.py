"""Typed parameter sets: dataclasses filled from YAML mappings with checks.

Every parameter set of the stack (MPC settings, simulated robot, sim node)
is a frozen dataclass whose defaults carry the units in comments. This module
fills one from a mapping, checking names and types, so a typo in a YAML file
is a clear error instead of a silently ignored key.
"""

import json
import math
from dataclasses import fields, replace

from puzzlebot_common.errors import ConfigError


def _coerce(default, value, where):
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError("%s: expected true or false, got %r" % (where, value))
        return value
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError("%s: expected a string, got %r" % (where, value))
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError("%s: expected an integer, got %r" % (where, value))
        return value
    if isinstance(default, float):
        if isinstance(value, str):
            # YAML 1.1 (PyYAML, rosparam) reads "1.0e3" as a string; accept it as the number it is.
            try:
                value = float(value)
            except ValueError:
                pass
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError("%s: expected a finite number, got %r" % (where, value))
        return float(value)
    return value


def check_keys(data, allowed, where):
    """Raise ConfigError naming ``where`` and the allowed keys when mapping ``data`` has any other key."""
    unknown = set(data) - set(allowed)
    if unknown:
        raise ConfigError("%s: unknown key(s) %s; allowed: %s"
                          % (where, ", ".join(sorted(map(str, unknown))), ", ".join(sorted(allowed))))


def from_mapping(cls, data, where):
    """Instance of dataclass ``cls`` with defaults overridden by ``data``.

    Unknown keys and values of the wrong type raise ConfigError naming
    ``where.key``. If the class defines ``check(where)``, it is called for
    range and cross-field checks.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError("%s: expected a mapping, got %r" % (where, data))
    defaults = cls()
    known = {f.name for f in fields(cls)}
    unknown = sorted(str(k) for k in set(data) - known)
    if unknown:
        raise ConfigError("%s: unknown key(s) %s; known: %s" % (where, ", ".join(unknown), ", ".join(sorted(known))))
    values = {k: _coerce(getattr(defaults, k), v, "%s.%s" % (where, k)) for k, v in data.items()}
    obj = replace(defaults, **values)
    check = getattr(obj, "check", None)
    if check is not None:
        check(where)
    return obj


def key_values(items, option):
    """{key: value} from command-line ``KEY=VALUE`` strings (``option`` names the flag in errors).

    A value is parsed as JSON when it can be (numbers, lists, true/false),
    else kept as a string; the caller checks keys and types (from_mapping).
    """
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("%s expects KEY=VALUE, got %r" % (option, item))
        try:
            out[key.strip()] = json.loads(value)
        except ValueError:
            out[key.strip()] = value
    return out


def require_positive(obj, names, where):
    """Raise ConfigError unless every named field of ``obj`` is > 0."""
    for name in names:
        if not getattr(obj, name) > 0:
            raise ConfigError("%s.%s: must be > 0, got %r" % (where, name, getattr(obj, name)))
