"""Diagnostic statuses of the stack's nodes, without ROS (diagnostic_msgs in the node shells).

Every node reports its health as ``Status`` objects; the node turns a list of
them into a diagnostic_msgs/DiagnosticArray on /diagnostics
(``puzzlebot_common.node_utils.diagnostic_array``). A status name starts with
the node's part of the stack (``puzzlebot_sim``, ``puzzlebot_mpc``,
``puzzlebot_driver``): the aggregator in puzzlebot_bringup
(config/diagnostics.yaml) groups by that prefix.
"""

from dataclasses import dataclass, field
from typing import List, Sequence, Tuple

# diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3


@dataclass
class Status:
    name: str
    level: int
    message: str
    hardware_id: str = ""
    values: List[Tuple[str, str]] = field(default_factory=list)


def fmt(x, spec="%.3f"):
    """``spec % x``, or "n/a" for None or NaN."""
    return "n/a" if x is None or x != x else spec % x


def worst(levels: Sequence[int]):
    """The highest of ``levels`` (OK for none)."""
    return max(levels, default=OK)
