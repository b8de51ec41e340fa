"""Model identification: close the loop between the MPC's model and measured data.

``identify(path)`` reads a bag or CSV of mocap poses and commands, measures
the open-loop prediction error of the nominal unicycle, traces the residual to
the actuator effects of ``puzzlebot_common.effects`` that explain it, adds those
that earn their place on validation data, and analyses what remains.
docs/model-identification.md describes the method; cli.py is the command line.
"""

from puzzlebot_mpc.identify.core import Result, identify  # noqa: F401
from puzzlebot_mpc.identify.data import DataError, load  # noqa: F401
from puzzlebot_mpc.identify.settings import IdentifySettings  # noqa: F401
