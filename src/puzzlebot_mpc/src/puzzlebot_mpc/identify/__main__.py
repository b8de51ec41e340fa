"""python -m puzzlebot_mpc.identify DATA --out report.json ... (see cli.py)."""

import sys

from puzzlebot_mpc.identify.cli import main

sys.exit(main())
