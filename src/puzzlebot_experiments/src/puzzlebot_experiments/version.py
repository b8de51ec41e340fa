"""The version of a trial's result: what the trial computes with, not how the code is laid out.

A result file keeps every trial with the version it was computed at; a sweep
reuses a result only at the same version. The version hashes

- the *configuration* a trial loads (the YAML files' parsed content: values,
  not comments or layout), and
- the *code* a trial runs: every module of the packages it executes
  (common, model, controller, simulator, the experiment harness), each
  reduced to its top-level definitions with docstrings, comments, imports
  and formatting removed (``ast``). The definitions are hashed as a sorted
  set, so moving a function to another module, renaming a file, editing a
  docstring or reordering imports keeps the version; changing what any
  statement computes changes it.

Modules that only report (tables, figures, the suite's driver) or only
adapt to ROS are left out: they cannot change a trial's outcome.
"""

import ast
import hashlib
import importlib
import json
import os
import subprocess

import yaml

from puzzlebot_common.config import shipped_config

#: package -> the shipped configuration files a trial loads
CONFIG_FILES = {
    "puzzlebot_sim": ("robot.yaml", "sim.yaml", "mocap_vicon.yaml"),
    "puzzlebot_mpc": ("mpc.yaml", "mpc_sim.yaml", "targets.yaml"),
    "puzzlebot_experiments": ("experiments.yaml",),
}

#: packages whose modules a trial runs
TRIAL_PACKAGES = ("puzzlebot_common", "puzzlebot_mpc", "puzzlebot_sim", "puzzlebot_experiments")

#: modules (paths relative to the package's module directory) that cannot change a trial's outcome
NOT_RUN_BY_TRIALS = {
    "puzzlebot_common": ("node_utils.py",),
    "puzzlebot_mpc": ("ros_conversions.py", "bench.py", "identify"),
    "puzzlebot_sim": ("ros_conversions.py", "lockstep.py", "stepper.py", "wall_clock.py"),   # the node's loop
    "puzzlebot_experiments": ("results_page.py", "experiment_suite.py", "version.py", "loop_demo.py",
                              "scenario_trials.py", "sensitivity.py", "executors.py", "speed_grid.py",
                              "pull_check.py"),
}


def package_dir(package):
    """The directory of a package's Python modules. In a catkin devel space the package's
    ``__init__`` is a generated stub whose ``__path__`` also names the source directory: the
    directory taken is the one that holds modules besides ``__init__.py``."""
    module = importlib.import_module(package)
    for d in module.__path__:
        if any(f.endswith(".py") and f != "__init__.py" for f in os.listdir(d)):
            return d
    raise RuntimeError("no modules found for package %s in %s" % (package, list(module.__path__)))


def source_files():
    """The Python sources a trial runs, sorted."""
    out = []
    for package in TRIAL_PACKAGES:
        root = package_dir(package)
        skip = NOT_RUN_BY_TRIALS.get(package, ())
        for d, dirs, files in os.walk(root):
            rel = os.path.relpath(d, root)
            dirs[:] = sorted(x for x in dirs if os.path.normpath(os.path.join(rel, x)) not in skip
                             and x != "__pycache__")
            out += [os.path.join(d, f) for f in files
                    if f.endswith(".py") and os.path.normpath(os.path.join(rel, f)) not in skip]
    return sorted(out)


def config_files():
    return [shipped_config(package, name) for package, names in sorted(CONFIG_FILES.items()) for name in names]


def _strip_docstrings(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                    and isinstance(body[0].value.value, str):
                node.body = body[1:] or [ast.Pass()]
    return tree


def definitions(source):
    """The top-level statements of a module's source, normalised (no docstrings, comments, imports), as text."""
    tree = _strip_docstrings(ast.parse(source))
    return [ast.unparse(node) for node in tree.body if not isinstance(node, (ast.Import, ast.ImportFrom))]


def code_digest(paths=None):
    """Hash of the sorted normalised definitions of ``paths`` (default: :func:`source_files`)."""
    defs = []
    for path in paths or source_files():
        with open(path) as f:
            defs += definitions(f.read())
    h = hashlib.sha1()
    for d in sorted(defs):
        h.update(d.encode())
        h.update(b"\0")
    return h.hexdigest()


def config_digest(paths=None):
    """Hash of the parsed content of the configuration files (values, not comments)."""
    h = hashlib.sha1()
    for path in paths or config_files():
        with open(path) as f:
            h.update(json.dumps(yaml.safe_load(f), sort_keys=True).encode())
    return h.hexdigest()


def config_hash(overrides=None):
    """A result's version: configuration, code and any setting overrides, 10 hex digits."""
    h = hashlib.sha1()
    h.update(config_digest().encode())
    h.update(code_digest().encode())
    if overrides:
        h.update(json.dumps(overrides, sort_keys=True).encode())
    return h.hexdigest()[:10]


def code_version():
    """``git describe`` of the source tree (with -dirty), or "unknown" outside a git checkout."""
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=here, capture_output=True,
                             text=True, timeout=10)
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"
