"""Rate-limited log lines, without ROS: at most one line per key and period.

The nodes log through it what can repeat at the input rate (rejected poses,
rejected commands, invalid controller output): the first line of a key goes
out at once, later ones at most every ``period`` seconds, each saying how
many lines of that key it held back.
"""

import time


class Throttle:
    def __init__(self, period, clock=time.monotonic):
        """``period`` [s]; ``clock()``: monotonic seconds (injectable for tests)."""
        self.period = period
        self.clock = clock
        self._last = {}
        self._held = {}

    def __call__(self, key, text):
        """The line to log now for ``key`` (with the count held back since the last one), or None."""
        now = self.clock()
        if now - self._last.get(key, -float("inf")) < self.period:
            self._held[key] = self._held.get(key, 0) + 1
            return None
        self._last[key] = now
        held = self._held.pop(key, 0)
        return text + (" (%d similar message(s) suppressed)" % held if held else "")
