"""Parameter tables in the docs, generated from the dataclasses that hold the defaults.

A page marks a table with two comments naming the class::

    <!-- BEGIN params puzzlebot_sim.params.SimParams -->
    <!-- END params puzzlebot_sim.params.SimParams -->

and :func:`rewrite` fills the block with one row per field: its key, its
default and the comment written beside it in the class (unit and meaning;
comment lines continuing it count, a comment line of its own above a field
is a heading and does not). So the page shows the values the code uses, and
``--check`` (a test runs it) fails when a default changed and the page did not::

    scripts/env.sh python -m puzzlebot_common.param_docs docs/sim.md            # rewrite the blocks
    scripts/env.sh python -m puzzlebot_common.param_docs --check docs/*.md      # exit 1 if one is stale
"""

import argparse
import ast
import dataclasses
import importlib
import inspect
import io
import re
import sys
import textwrap
import tokenize

from puzzlebot_common.errors import ConfigError

BLOCK = re.compile(r"(<!-- BEGIN params (?P<cls>[\w.]+) -->\n)(?P<body>.*?)(<!-- END params (?P=cls) -->)", re.S)


def field_comments(cls):
    """{field name: the comment beside it and its continuation lines, joined} of a dataclass."""
    source = textwrap.dedent(inspect.getsource(cls))
    comments = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = (tok.start[1], tok.string.lstrip("#"), tok.line.strip().startswith("#"))
    body = ast.parse(source).body[0].body
    fields = [node for node in body if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)]
    out = {}
    for k, node in enumerate(fields):
        indent = node.col_offset
        stop = fields[k + 1].lineno if k + 1 < len(fields) else node.end_lineno + 50
        parts = [comments[node.end_lineno][1].strip()] if node.end_lineno in comments else []
        for line in range(node.end_lineno + 1, stop):
            if line not in comments:
                break
            col, text, own_line = comments[line]
            if not own_line or not (col > indent or text.startswith("  ")):    # a heading, not a continuation
                break
            parts.append(text.strip())
        out[node.target.id] = " ".join(p for p in parts if p)
    return out


def _value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"%s"' % v
    if isinstance(v, (tuple, list)):
        return "[%s]" % ", ".join(_value(x) for x in v)
    return repr(v)


def table(cls):
    """Markdown table of a dataclass's fields: key, default, unit and meaning."""
    notes = field_comments(cls)
    rows = ["| key | default | unit, meaning |", "| --- | --- | --- |"]
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        cells = (_value(default), notes.get(f.name, ""))
        rows.append("| `%s` | %s | %s |" % ((f.name,) + tuple(c.replace("|", "\\|") for c in cells)))
    return "\n".join(rows) + "\n"


def dataclass_by_name(dotted):
    module, _, name = dotted.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError, ValueError) as e:
        raise ConfigError("params block %s: no such class (%s)" % (dotted, e)) from None
    if not dataclasses.is_dataclass(cls):
        raise ConfigError("params block %s: not a dataclass" % dotted)
    return cls


def rewrite_text(text):
    """``text`` with every params block regenerated, and the classes named."""
    names = []

    def fill(m):
        names.append(m.group("cls"))
        return m.group(1) + table(dataclass_by_name(m.group("cls"))) + m.group(4)

    return BLOCK.sub(fill, text), names


def rewrite(path, check=False):
    """Regenerate the params blocks of a page (``check``: only report). Returns True when the page was current."""
    with open(path) as f:
        text = f.read()
    new, _ = rewrite_text(text)
    if new != text and not check:
        with open(path, "w") as f:
            f.write(new)
    return new == text


def main(argv=None):
    ap = argparse.ArgumentParser(description="regenerate the parameter tables of doc pages")
    ap.add_argument("pages", nargs="+")
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if a table is stale")
    args = ap.parse_args(argv)
    stale = [p for p in args.pages if not rewrite(p, check=args.check)]
    for p in stale:
        print("%s: parameter tables %s" % (p, "stale" if args.check else "rewritten"))
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
