"""The ESP8266 wheel-command protocol of the lab's robots.

The host is a TCP server (port 8080 by default); each robot connects as a
client and is identified by the last octet of its IP address. The host sends
one ASCII line per command: ``"%04d,%04d\\n"`` = left, right motor PWM, each
in -250..250 (e.g. ``"0120,-045\\n"``). The firmware keeps the last PWM until
the next line arrives: it has no timeout of its own.
"""

import ipaddress
import re

PWM_LIMIT = 250
_LINE_RE = re.compile(r"^\s*(-?\d{1,4})\s*,\s*(-?\d{1,4})\s*$")


class ProtocolError(ValueError):
    """A PWM line or an address does not follow the protocol."""


def format_pwm(left, right):
    """Encode integer PWM values as one protocol line (bytes)."""
    for side, value in (("left", left), ("right", right)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProtocolError("%s PWM must be an integer, got %r" % (side, value))
        if not -PWM_LIMIT <= value <= PWM_LIMIT:
            raise ProtocolError("%s PWM %d outside -%d..%d" % (side, value, PWM_LIMIT, PWM_LIMIT))
    return ("%04d,%04d\n" % (left, right)).encode("ascii")


def parse_pwm(line):
    """Decode one protocol line (bytes or str, with or without newline) to (left, right)."""
    if isinstance(line, bytes):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError:
            raise ProtocolError("PWM line is not ASCII: %r" % line) from None
    m = _LINE_RE.match(line.rstrip("\r\n"))
    if not m:
        raise ProtocolError("not a PWM line: %r" % line)
    left, right = int(m.group(1)), int(m.group(2))
    if not (-PWM_LIMIT <= left <= PWM_LIMIT and -PWM_LIMIT <= right <= PWM_LIMIT):
        raise ProtocolError("PWM out of range -%d..%d: %r" % (PWM_LIMIT, PWM_LIMIT, line))
    return left, right


def ip_last_octet(address):
    """Last octet of an IPv4 address string (how the lab identifies a robot)."""
    try:
        ip = ipaddress.IPv4Address(address)
    except ValueError:
        raise ProtocolError("not an IPv4 address: %r" % (address,)) from None
    return int(str(ip).rsplit(".", 1)[1])
