"""The docs' parameter tables are the defaults the code uses (puzzlebot_common.param_docs, ROS-free)."""

import glob
import os

import pytest

from puzzlebot_common.param_docs import BLOCK, rewrite

DOCS = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "docs"))
PAGES = sorted(glob.glob(os.path.join(DOCS, "*.md")))


def test_the_docs_have_parameter_tables():
    with open(os.path.join(DOCS, "sim.md")) as f:
        assert len(BLOCK.findall(f.read())) >= 5       # RobotParams, AnchorParams, SimParams, WorldParams, anchor_rest


@pytest.mark.parametrize("page", PAGES, ids=os.path.basename)
def test_parameter_tables_are_current(page):
    assert rewrite(page, check=True), \
        "%s: a default changed; run scripts/env.sh python -m puzzlebot_common.param_docs %s" % (page, page)
