"""``stop``: every robot comes to rest (the rest state between behaviours, requested). Succeeds at
the first control step."""

from puzzlebot_mpc.behaviors.base import SUCCEEDED, Behavior, Progress

STOP = "stop"


class Stop(Behavior):
    name = STOP

    def status(self, now, poses, newly, lost, elapsed):
        return Progress(SUCCEEDED, "stopped")
