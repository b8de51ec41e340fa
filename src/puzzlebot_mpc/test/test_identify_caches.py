"""The identification's caches change nothing: warm results are bit for bit the cold ones.

A fit evaluates thousands of parameter sets on the same windows; what does not
depend on the varied parameter is kept: per command-piece structure the
quantities derived from the pieces alone (effects.CommandPieces.derived), per
window set the integrated heading and path of recent velocity signals
(engine._path), per robot the errors of recent parameter sets
(fit.RobotFit.errors). Each is checked against the same computation from
scratch, in the order a fit varies the parameters (one at a time, back and
forth, repeated).
"""

import os
from dataclasses import replace

import numpy as np
import pytest

import identify_synth as synth
from puzzlebot_common.effects import NOMINAL, actuator_velocities, command_pieces
from puzzlebot_mpc.identify import IdentifySettings, cli, engine, fit
from puzzlebot_mpc.identify.data import RobotData

BASE = dict(NOMINAL, delay_s=0.08, v_min=0.01, w_min=0.1, k_v=0.9, k_w=1.1, tau_v_s=0.12, tau_w_s=0.07)
#: Parameter sets in the order a fit might try them: one parameter at a time, some repeated.
SEQUENCE = [BASE, dict(BASE, k_v=0.91), dict(BASE, k_w=1.11), dict(BASE, offset_rad=0.05), BASE,
            dict(BASE, v_min=0.02), dict(BASE, w_min=0.2), dict(BASE, tau_v_s=0.2), dict(BASE, tau_w_s=0.0),
            dict(BASE, w_per_v=0.5), dict(BASE, w0=0.02), dict(BASE, rate_per_s=-0.004),
            dict(BASE, rate_per_s=-0.004, k_v=0.95), dict(BASE, a_v=0.4, a_w=8.0), dict(BASE, a_v=0.5, a_w=8.0),
            dict(BASE, a_v=0.4, a_w=9.0), dict(BASE, a_v=0.4, a_w=8.0), dict(BASE, delay_s=0.1), BASE,
            dict(BASE, k_v=0.91), dict(BASE, v_c=0.004, w_c=0.05), dict(BASE, delay_s=0.0, tau_v_s=0.0)]


def bits(a):
    return np.asarray(a).view(np.int64)


def assert_identical(a, b):
    for x, y in zip(a, b):
        assert x.shape == y.shape and np.array_equal(bits(x), bits(y))


@pytest.fixture(scope="module")
def robot():
    rec = synth.lab_record({"velocity_lag": {"tau_v_s": 0.1, "tau_w_s": 0.1}}, n_robots=1, duration=30.0, seed=5)
    r = rec["pz1"]
    t, v, w = (np.array(c) for c in zip(*r["cmd"]))
    return RobotData("pz1", r["t"], r["x"], r["y"], r["yaw"], t, v, w, t_start=float(r["t"][0]))


def test_velocities_with_kept_pieces_are_those_of_fresh_pieces(robot):
    r, dt, n, t0 = robot, 0.01, 2500, float(robot.cmd_t[0]) - 0.5
    kept = {}
    for params in SEQUENCE:
        delay = params["delay_s"]
        if delay not in kept:
            kept[delay] = command_pieces(r.cmd_t, delay, t0, dt, n)
        warm = actuator_velocities(params, r.cmd_t, r.cmd_v, r.cmd_w, t0, dt, n, pieces=kept[delay], t_start=1.0)
        cold = actuator_velocities(params, r.cmd_t, r.cmd_v, r.cmd_w, t0, dt, n, t_start=1.0)
        assert_identical(warm, cold)
    assert kept[BASE["delay_s"]].derived          # something was kept


def test_predictions_with_warm_caches_are_the_cold_ones(robot):
    w = engine.robot_windows(robot, IdentifySettings())
    for params in SEQUENCE:
        warm = engine.predict(params, robot, w)
        cold = engine.predict(params, robot, replace(w, cache={}, paths=[]))
        assert_identical(warm, cold)
    assert 0 < len(w.paths) <= engine.PATH_CACHE


def test_robot_fit_remembers_errors(robot):
    rf = fit.RobotFit(robot, IdentifySettings())
    first = rf.errors(BASE)
    evaluated = rf.nfev
    again = rf.errors(dict(BASE))
    assert again is first and rf.nfev == evaluated                 # a look-up, not an evaluation
    assert not first[0].flags.writeable and not first[1].flags.writeable
    assert_identical(first, engine.errors(BASE, robot, replace(rf.windows, cache={}, paths=[])))
    for k in range(fit.ERRORS_CACHE):
        rf.errors(dict(BASE, k_v=1.0 + 1e-3 * k))
    assert rf.errors(BASE) is not first and rf.nfev == evaluated + fit.ERRORS_CACHE + 1   # dropped, re-evaluated


def test_blas_threads_are_left_alone_when_the_user_chose(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    assert cli.one_blas_thread() == []
    assert os.environ["OPENBLAS_NUM_THREADS"] == "2"


def test_blas_runs_on_one_thread_otherwise(monkeypatch):
    from threadpoolctl import threadpool_info

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    libs = cli.one_blas_thread()
    assert libs and all(lib["num_threads"] == 1 for lib in libs)
    assert all(i["num_threads"] == 1 for i in threadpool_info() if i["user_api"] == "blas")
