"""rosdep can set up the workspace: every key the package.xml files declare resolves on Debian 12 (the
shipped source rosdep/puzzlebot.yaml, then Debian's rules), to apt packages scripts/setup.sh installs and
pip packages requirements.txt pins; and ``rosdep check`` (scripts/rosdep.sh) reports them satisfied."""

import os
import re
import subprocess
import xml.etree.ElementTree as ET

import pytest
import yaml

SRC = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
ROOT = os.path.dirname(SRC)
DEBIAN_RULES = "/usr/share/python3-rosdep2/debian.yaml"
TAGS = ("depend", "exec_depend", "build_depend", "buildtool_depend", "test_depend", "build_export_depend")


def declared_keys():
    packages = [p for p in os.listdir(SRC) if os.path.isfile(os.path.join(SRC, p, "package.xml"))]
    keys = set()
    for p in packages:
        root = ET.parse(os.path.join(SRC, p, "package.xml")).getroot()
        keys |= {e.text.strip() for tag in TAGS for e in root.iter(tag)}
    return keys - set(packages)


def debian_rule(key, sources):
    """The debian rule of ``key`` in the first source defining it: ("apt", [...]) or ("pip", [...])."""
    for source in sources:
        if key in source and "debian" in source[key]:
            rule = source[key]["debian"]
            if isinstance(rule, dict) and "pip" in rule:
                return "pip", list(rule["pip"]["packages"])
            return "apt", list(rule["apt"]["packages"] if isinstance(rule, dict) else rule)
    return None


def setup_apt_packages():
    with open(os.path.join(ROOT, "scripts", "setup.sh")) as f:
        text = f.read()
    block = re.search(r"^APT_PACKAGES=\((.*?)^\)", text, re.S | re.M).group(1)
    return {w for line in block.splitlines() for w in line.split("#")[0].split()}


def pinned_pip_packages():
    with open(os.path.join(ROOT, "requirements.txt")) as f:
        return {line.split("==")[0].strip().lower() for line in f if "==" in line and not line.startswith("#")}


@pytest.mark.skipif(not os.path.isfile(DEBIAN_RULES), reason="Debian's rosdep rules (python3-rosdep2) not installed")
def test_every_key_resolves_to_what_make_setup_installs():
    with open(os.path.join(ROOT, "rosdep", "puzzlebot.yaml")) as f:
        ours = yaml.safe_load(f)
    with open(DEBIAN_RULES) as f:
        debian = yaml.safe_load(f)
    apt, pip, unresolved = set(), set(), []
    for key in sorted(declared_keys()):
        rule = debian_rule(key, [ours, debian])
        if rule is None:
            unresolved.append(key)
        else:
            (apt if rule[0] == "apt" else pip).update(rule[1])
    assert not unresolved, "keys without a Debian rule: %s" % unresolved
    assert apt - setup_apt_packages() == set(), "apt packages scripts/setup.sh does not install"
    assert {p.lower() for p in pip} - pinned_pip_packages() == set(), "pip packages requirements.txt lacks"
    assert {"casadi", "pybullet", "clarabel"} <= pip


@pytest.mark.skipif(subprocess.run(["which", "rosdep"], capture_output=True).returncode != 0,
                    reason="rosdep (python3-rosdep2) not installed")
def test_rosdep_check_is_satisfied():
    proc = subprocess.run([os.path.join(ROOT, "scripts", "rosdep.sh"), "check"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and "All system dependencies have been satisfied" in proc.stdout, \
        proc.stdout + proc.stderr
