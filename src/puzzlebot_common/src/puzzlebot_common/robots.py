"""The robot list: which robots exist and what they are called.

A robot list is a YAML sequence of mappings (usually under the key
``robots``)::

    robots:
      - name: pz1            # required; used in topics and frames
        pilot: false         # optional; pilot robots have four driven wheels
        mocap: pz1           # optional; motion-capture subject, default = name
        ip_octet: 21         # optional; last octet of the robot's IP (lab only)

Names come only from such lists, never from code.
"""

import re
from dataclasses import dataclass
from typing import Optional

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.names import vicon_topic
from puzzlebot_common.params import check_keys

_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_KNOWN_KEYS = {"name", "pilot", "mocap", "ip_octet"}


@dataclass(frozen=True)
class RobotSpec:
    """One robot of the list."""

    name: str
    pilot: bool = False
    mocap: Optional[str] = None
    ip_octet: Optional[int] = None

    @property
    def mocap_subject(self):
        """Motion-capture subject name (defaults to the robot name)."""
        return self.mocap or self.name

    @property
    def vicon_topic(self):
        """Topic on which this robot's measured pose arrives."""
        return vicon_topic(self.mocap_subject)


def _check_name(value, where):
    if not isinstance(value, str) or not _NAME_RE.match(value):
        raise ConfigError(
            "%s: expected a robot name (letter then letters, digits or '_'), got %r"
            % (where, value))
    return value


def parse_robot(entry, where="robot"):
    """Build a :class:`RobotSpec` from one mapping; raise ConfigError if malformed."""
    if isinstance(entry, str):
        return RobotSpec(name=_check_name(entry, where))
    if not isinstance(entry, dict):
        raise ConfigError("%s: expected a mapping with at least 'name', got %r" % (where, entry))
    check_keys(entry, _KNOWN_KEYS, where)
    if "name" not in entry:
        raise ConfigError("%s: missing 'name'" % where)
    name = _check_name(entry["name"], where + ".name")
    pilot = entry.get("pilot", False)
    if not isinstance(pilot, bool):
        raise ConfigError("%s.pilot: expected true or false, got %r" % (where, pilot))
    mocap = entry.get("mocap")
    if mocap is not None:
        _check_name(mocap, where + ".mocap")
    ip_octet = entry.get("ip_octet")
    if ip_octet is not None and (isinstance(ip_octet, bool) or not isinstance(ip_octet, int)
                                 or not 1 <= ip_octet <= 254):
        raise ConfigError("%s.ip_octet: expected an integer 1..254, got %r" % (where, ip_octet))
    return RobotSpec(name=name, pilot=pilot, mocap=mocap, ip_octet=ip_octet)


def parse_robot_list(data, where="robots"):
    """Parse a robot list (a sequence, or a mapping holding one under ``robots``).

    Returns a list of :class:`RobotSpec` in file order. Raises ConfigError on
    an empty list, malformed entries, or duplicate names, mocap subjects or
    IP octets.
    """
    if isinstance(data, dict) and "robots" in data:
        data = data["robots"]
    if not isinstance(data, (list, tuple)):
        raise ConfigError("%s: expected a list of robots, got %s" % (where, type(data).__name__))
    if not data:
        raise ConfigError("%s: the robot list is empty" % where)
    specs = [parse_robot(e, "%s[%d]" % (where, i)) for i, e in enumerate(data)]
    for attr, label in (("name", "name"), ("mocap_subject", "mocap subject"), ("ip_octet", "ip_octet")):
        seen = {}
        for i, spec in enumerate(specs):
            value = getattr(spec, attr)
            if value is None:
                continue
            if value in seen:
                raise ConfigError("%s[%d]: duplicate %s %r (also robots[%d])"
                                  % (where, i, label, value, seen[value]))
            seen[value] = i
    return specs


def robot_names(specs):
    """Names of a parsed robot list, in order."""
    return [s.name for s in specs]
