"""Wall time and blocking waits for the sim node's loop (lockstep.Lockstep, stepper.Stepper).

The loop's cores take the clock as an argument: the node gives them a
``WallClock``, a unit test a fake with the same three methods whose time
moves only when the code under test waits or sleeps.
"""

import time


class WallClock:
    """Monotonic wall time [s], sleeping, and waiting on a condition variable."""

    @staticmethod
    def now():
        return time.monotonic()

    @staticmethod
    def sleep(seconds):
        time.sleep(seconds)

    @staticmethod
    def wait(condition, predicate, timeout):
        """Wait (holding ``condition``) until ``predicate()`` or ``timeout`` s; returns ``predicate()``."""
        return condition.wait_for(predicate, timeout)
