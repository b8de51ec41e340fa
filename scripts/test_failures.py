#!/usr/bin/env python3
"""Print what every failed or erroring test case said, from the JUnit XML files under a directory.

scripts/run_tests.sh calls it at the end of a failed run, so the last lines of the output (what a CI
log shows) name the failure and its message, not only the count catkin_test_results gives.
Usage: scripts/test_failures.py DIR [MAX_LINES]   (MAX_LINES per failure, default 40)
"""

import pathlib
import sys
import xml.etree.ElementTree as ET


def failures(root):
    """(file, test case, kind, text, output) of every <failure>/<error> in the XML files under ``root``;
    ``output``: the last lines of what the test printed (the case's or its suite's system-out)."""
    for path in sorted(pathlib.Path(root).rglob("*.xml")):
        try:
            tree = ET.parse(path)
        except ET.ParseError as e:
            yield path, "-", "unreadable", "%s" % e, ""
            continue
        suite_out = "\n".join(n.text or "" for n in tree.getroot().findall("system-out"))
        for case in tree.iter("testcase"):
            out = "\n".join(n.text or "" for n in case.findall("system-out")) or suite_out
            for kind in ("failure", "error"):
                for node in case.findall(kind):
                    text = "\n".join(t for t in (node.get("message"), node.text) if t and t.strip())
                    yield path, "%s.%s" % (case.get("classname", ""), case.get("name", "")), kind, text, out


def main(argv):
    root = argv[1] if len(argv) > 1 else "build/test_results"
    max_lines = int(argv[2]) if len(argv) > 2 else 40
    for path, case, kind, text, out in failures(root):
        lines = text.strip().splitlines()
        print("-- %s %s (%s)" % (kind.upper(), case, path.relative_to(root)))
        for line in lines[:max_lines]:
            print("   " + line)
        if len(lines) > max_lines:
            print("   ... (%d more lines)" % (len(lines) - max_lines))
        printed = [line for line in out.replace("<![CDATA[", "").replace("]]>", "").splitlines() if line.strip()]
        if printed:
            print("   what it printed last:")
            for line in printed[-15:]:
                print("   | " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
