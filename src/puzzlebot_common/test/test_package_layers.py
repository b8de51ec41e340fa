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
#: some (an import inside a function) and its test checks that; node_utils is common's rospy adapter;
#: rostest_lab is the lab of the node rostests (only they import it).
ALLOWED = {
    os.path.join("puzzlebot_common", "src", "puzzlebot_common", "model.py"): {"casadi"},
    os.path.join("puzzlebot_common", "src", "puzzlebot_common", "node_utils.py"): {"rospy"},
    os.path.join("puzzlebot_common", "src", "puzzlebot_common", "rostest_lab.py"): {"rospy"},
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


#: Module -> the rosdep key that provides it (rosdep/puzzlebot.yaml and Debian's rosdep data resolve
#: each). The Python standard library and the workspace's own packages need none.
MODULE_KEYS = {
    "numpy": "python3-numpy", "scipy": "python3-scipy", "matplotlib": "python3-matplotlib", "yaml": "python3-yaml",
    "PIL": "python3-pil", "dateutil": "python3-dateutil", "pytest": "python3-pytest", "rospkg": "python3-rospkg",
    "casadi": "casadi", "clarabel": "clarabel", "qdldl": "qdldl", "threadpoolctl": "threadpoolctl",
    "distributed": "dask-distributed",
    "dask": "dask-distributed", "pybullet": "pybullet", "pybullet_data": "pybullet",
    "rospy": "rospy", "rosgraph": "rosgraph", "roslaunch": "roslaunch", "rostest": "rostest", "rosbag": "rosbag",
    "roslz4": "rosbag", "rosunit": "rostest", "genpy": "genpy", "tf2_ros": "tf2_ros", "tf2_msgs": "tf2_msgs",
    "actionlib": "actionlib", "actionlib_msgs": "actionlib_msgs", "dynamic_reconfigure": "dynamic_reconfigure",
    "rosdiagnostic": "rosdiagnostic", "std_msgs": "std_msgs", "geometry_msgs": "geometry_msgs",
    "sensor_msgs": "sensor_msgs", "visualization_msgs": "visualization_msgs", "diagnostic_msgs": "diagnostic_msgs",
    "rosgraph_msgs": "rosgraph_msgs",
}
#: Imports a file makes only when a caller hands it such objects (model.py: CasADi symbols); the package
#: need not depend on them (a test_depend covers the test that does).
OPTIONAL = {os.path.join("puzzlebot_common", "src", "puzzlebot_common", "model.py"): {"casadi"}}


def third_party(path, package):
    """Modules a file imports that are neither the standard library, a workspace package nor a module
    beside it (a test's helper)."""
    import sys

    here = os.path.dirname(path)
    return {m for m in imports(path) if m not in sys.stdlib_module_names and not m.startswith("puzzlebot_")
            and m != package and not os.path.isfile(os.path.join(here, m + ".py"))}


def is_test(path, package):
    return os.path.relpath(path, os.path.join(SRC, package)).split(os.sep)[0] == "test"


@pytest.mark.parametrize("package", packages())
def test_every_module_imported_is_a_declared_dependency(package):
    """package.xml declares the rosdep key of every module the package imports (tests: at least as
    test_depend), so rosdep installs what it needs (rosdep/puzzlebot.yaml, README)."""
    declared_keys = declared(package)
    tree = ET.parse(os.path.join(SRC, package, "package.xml")).getroot()
    runtime = {e.text.strip() for tag in ("depend", "exec_depend", "buildtool_depend") for e in tree.iter(tag)}
    bad = []
    for path in python_files(package):
        rel = os.path.relpath(path, SRC)
        if os.path.basename(path) == "setup.py":
            continue                    # catkin_python_setup's: the build tool (catkin) provides it
        for module in sorted(third_party(path, package) - OPTIONAL.get(rel, set())):
            key = MODULE_KEYS.get(module)
            if key is None:
                bad.append("%s imports %s: no rosdep key known (MODULE_KEYS)" % (rel, module))
            elif key not in (declared_keys if is_test(path, package) else runtime):
                bad.append("%s imports %s: %s/package.xml lacks %s%s" % (rel, module, package, key,
                                                                        "" if is_test(path, package) else
                                                                        " (exec_depend)"))
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", packages())
def test_every_package_a_launch_file_starts_is_declared(package):
    import re

    launch = os.path.join(SRC, package, "launch")
    used = set()
    for d, _, files in os.walk(launch):
        for f in files:
            with open(os.path.join(d, f)) as fh:
                text = fh.read()
            used |= set(re.findall(r'pkg="([^"$]+)"', text)) | set(re.findall(r"\$\(find ([\w]+)\)", text))
    missing = sorted(used - declared(package) - {package})
    assert not missing, "%s/package.xml does not declare %s (its launch files use them)" % (package, ", ".join(missing))
