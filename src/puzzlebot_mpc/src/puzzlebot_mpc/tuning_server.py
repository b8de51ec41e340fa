"""The MPC node's dynamic_reconfigure server (ROS side of puzzlebot_mpc.tuning): ``~tuning``.

    rosrun puzzlebot_mpc tune w_goal_terminal=20000       # nodes/tune (Debian's dynparam does not run)
    rosrun puzzlebot_mpc tune

(or dynamic_reconfigure.client.Client("/mpc/tuning").update_configuration({...}); no rqt on Debian 12).
A change is validated as the YAML is; refused, nothing changes and the answer's ``refused`` says why;
applied, it is used from the next control step (a weight or a limit: after the MPC's problem is built
anew in this thread; the time it took is logged). It starts at the node's settings (the YAML), whatever
a previous run left under ~tuning on the same parameter server.
"""

import time

import rospy
from dynamic_reconfigure.server import Server

from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.tuning import REFUSED, config_type, describe, tuned


class TuningServer:
    """``node``: the MPC node (lock, loop, settings)."""

    def __init__(self, node, namespace="tuning"):
        self.node = node
        self.where = rospy.resolve_name("~" + namespace)
        self.rebuild_ms = []          # wall time [ms] of each rebuild (tests, the log)
        if rospy.has_param(self.where):   # a previous run's live values (same roscore): start from the YAML
            rospy.delete_param(self.where)
        self.server = Server(config_type(node.loop.settings), self.on_config, namespace=namespace)

    def on_config(self, config, level):
        node = self.node
        with node.lock:
            settings, keys = node.loop.settings, node.loop.pair_keys()
        try:
            new, diff, rebuild = tuned(settings, config, where=self.where)
        except ConfigError as e:
            rospy.logerr("tuning refused: %s" % e)
            previous = dict(config)
            previous.update({k: getattr(settings, k) for k in previous if hasattr(settings, k)})
            previous[REFUSED] = str(e)
            return previous
        config[REFUSED] = ""
        if not diff:
            return config
        mpc, built = None, ""
        if rebuild:
            t0 = time.perf_counter()
            mpc = node.loop.build_mpc(new, keys)
            self.rebuild_ms.append(1e3 * (time.perf_counter() - t0))
            built = "; the MPC's problem rebuilt in %.0f ms" % self.rebuild_ms[-1]
        with node.lock:
            node.loop.retune(new, mpc)
            node.settings = new
        rospy.logwarn("tuning: %s (from the next control step%s)" % (describe(diff, settings), built))
        return config
