"""Parameter tables generated from dataclasses (puzzlebot_common.param_docs)."""

from dataclasses import dataclass
from typing import Tuple

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.param_docs import field_comments, main, rewrite_text, table


@dataclass(frozen=True)
class Example:
    """A docstring is not a comment."""

    # a heading above the fields
    rate: int = 100              # Hz, how often
    period: float = 0.1          # s, a comment that goes on
    #                              on the next line
    # another heading, not part of period's comment
    name: str = "a|b"            # a pipe in the text
    flag: bool = False
    profile: Tuple[float, ...] = (0.0, 0.5)
    #                              mm, a continuation under a field without a comment of its own


def test_comments_beside_a_field_and_their_continuation_lines_not_headings():
    assert field_comments(Example) == {"rate": "Hz, how often", "period": "s, a comment that goes on on the next line",
                                       "name": "a pipe in the text", "flag": "",
                                       "profile": "mm, a continuation under a field without a comment of its own"}


def test_table_rows_hold_key_default_and_comment():
    rows = table(Example).splitlines()
    assert rows[2:] == ["| `rate` | 100 | Hz, how often |",
                        "| `period` | 0.1 | s, a comment that goes on on the next line |",
                        '| `name` | "a\\|b" | a pipe in the text |',
                        "| `flag` | false |  |",
                        "| `profile` | [0.0, 0.5] | mm, a continuation under a field without a comment of its own |"]


def test_blocks_are_filled_and_a_stale_page_is_found(tmp_path):
    name = "puzzlebot_common.geometry.RobotGeometry"
    page = tmp_path / "page.md"
    page.write_text("text\n<!-- BEGIN params %s -->\nSTALE ROW\n<!-- END params %s -->\nmore\n" % (name, name))
    assert main(["--check", str(page)]) == 1 and "STALE ROW" in page.read_text()       # --check changes nothing
    assert main([str(page)]) == 0
    text = page.read_text()
    assert "| `wheel_base` | 0.04 |" in text and "STALE ROW" not in text and text.endswith("-->\nmore\n")
    assert main(["--check", str(page)]) == 0
    assert rewrite_text(text)[1] == [name]


def test_an_unknown_class_names_the_block():
    with pytest.raises(ConfigError, match="params block puzzlebot_common.geometry.Nope: no such class"):
        rewrite_text("<!-- BEGIN params puzzlebot_common.geometry.Nope -->\n"
                     "<!-- END params puzzlebot_common.geometry.Nope -->")
