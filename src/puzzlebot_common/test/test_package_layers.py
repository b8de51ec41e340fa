"""The packages' layering, read off their imports (ROS-free: the sources are parsed, not imported).

- puzzlebot_common (geometry, the unicycle model, the actuator effects) is the
  ground floor: it imports no other PuzzleBot package;
- the simulator and the driver stand on it beside the controller: neither
  imports puzzlebot_mpc (nor CasADi);
- no product package imports puzzlebot_experiments (the research lives apart);
- every PuzzleBot package a package imports is declared in its package.xml.
"""

import ast
import os
import xml.etree.ElementTree as ET

import pytest

SRC = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
PRODUCT = ("puzzlebot_msgs", "puzzlebot_common", "puzzlebot_mpc", "puzzlebot_sim", "puzzlebot_driver",
           "puzzlebot_bringup")
FORBIDDEN = {
    "puzzlebot_common": {"puzzlebot_mpc", "puzzlebot_sim", "puzzlebot_driver", "puzzlebot_bringup",
                         "puzzlebot_experiments", "puzzlebot_msgs", "casadi", "rospy", "pybullet"},
    "puzzlebot_sim": {"puzzlebot_mpc", "casadi", "puzzlebot_experiments"},
    "puzzlebot_driver": {"puzzlebot_mpc", "casadi", "puzzlebot_experiments"},
    "puzzlebot_mpc": {"puzzlebot_sim", "puzzlebot_driver", "puzzlebot_experiments", "pybullet"},
    "puzzlebot_bringup": {"puzzlebot_experiments"},
}
#: Exceptions: file -> imports it may make. The model works on CasADi symbols when a caller hands it
#: some (an import inside a function) and its test checks that; node_utils is common's rospy adapter.
ALLOWED = {
    os.path.join("puzzlebot_common", "src", "puzzlebot_common", "model.py"): {"casadi"},
    os.path.join("puzzlebot_common", "src", "puzzlebot_common", "node_utils.py"): {"rospy"},
}


def python_files(package, tests=True):
    """Every Python file of a package: modules, nodes, scripts (by shebang) and, with ``tests``, its tests."""
    root = os.path.join(SRC, package)
    for d, dirs, files in os.walk(root):
        dirs[:] = [x for x in dirs if x != "__pycache__" and (tests or x != "test")]
        for f in sorted(files):
            path = os.path.join(d, f)
            if f.endswith(".py"):
                yield path
            elif "." not in f:
                with open(path, "rb") as fh:
                    first = fh.readline()
                if first.startswith(b"#!") and b"python" in first:
                    yield path


def imports(path):
    """Top-level module names imported anywhere in a file."""
    with open(path) as f:
        tree = ast.parse(f.read(), filename=path)
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


def declared(package):
    tree = ET.parse(os.path.join(SRC, package, "package.xml"))
    tags = ("depend", "exec_depend", "build_depend", "test_depend", "build_export_depend")
    return {e.text.strip() for tag in tags for e in tree.getroot().iter(tag)}


def packages():
    return sorted(p for p in os.listdir(SRC) if os.path.isfile(os.path.join(SRC, p, "package.xml")))


def test_the_product_and_the_experiments_are_the_packages_of_the_tree():
    assert set(PRODUCT) | {"puzzlebot_experiments"} == set(packages())


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_layers(package):
    """The product code (modules, nodes, scripts) keeps the layers."""
    bad = []
    for path in python_files(package, tests=False):
        rel = os.path.relpath(path, SRC)
        found = (imports(path) & FORBIDDEN[package]) - ALLOWED.get(rel, set())
        bad += ["%s imports %s" % (rel, m) for m in sorted(found)]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", PRODUCT)
def test_no_product_test_needs_the_experiments(package):
    bad = [os.path.relpath(p, SRC) for p in python_files(package) if "puzzlebot_experiments" in imports(p)]
    assert not bad, "%s import puzzlebot_experiments" % ", ".join(bad)


@pytest.mark.parametrize("package", packages())
def test_every_puzzlebot_package_imported_is_declared(package):
    used = set()
    for path in python_files(package):
        used |= {m for m in imports(path) if m.startswith("puzzlebot_")}
    missing = sorted(used - declared(package) - {package})
    assert not missing, "%s/package.xml does not declare %s" % (package, ", ".join(missing))


def test_the_checks_see_a_forbidden_import(tmp_path):
    """The import reader finds imports inside functions and ``from`` forms (a layering test that cannot fail
    would prove nothing)."""
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from puzzlebot_mpc.effects import X\n    import casadi.tools as t\n")
    assert {"puzzlebot_mpc", "casadi"} <= imports(str(f))
