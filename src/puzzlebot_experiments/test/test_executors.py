"""Sweeps on the local process pool and on a Dask cluster (puzzlebot_experiments.executors).

The cluster is a local one of 2 worker processes started by the test on this
machine (``--cluster local:2``): the same scheduler and workers a lab's
cluster runs, on the loopback interface. The same seeds give the same records
on both, a sweep started on one continues on the other, and a worker running
other code is refused.
"""

import io
import json
import math
import os

import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_experiments import executors
from puzzlebot_experiments import experiments as ex

#: A seed the sweeps of docs/results.md do not use; decoupling trials take about 0.5 s each.
SEED = 915
TRIALS = 4


def _same(rec):
    """A record without its wall-clock time (the only field that depends on the machine's load)."""
    return {k: v for k, v in rec.items() if k != "wall_s"}


@pytest.fixture(scope="module")
def cluster():
    import distributed  # noqa: F401  (requirements.txt pins it: missing is a failed install, not a skip)

    try:
        c = executors.DaskCluster("local:2")
    except ConfigError as e:
        pytest.skip("a local Dask cluster cannot start on this machine: %s" % e)
    yield c
    c.close()


@pytest.fixture(scope="module")
def pool_records(tmp_path_factory):
    path = str(tmp_path_factory.mktemp("pool") / "results.jsonl")
    tasks = ex.tasks_for(ex.DECOUPLE, TRIALS, SEED)
    return ex.run_sweep(tasks, path, jobs=2, stream=io.StringIO())


def test_a_sweep_on_the_cluster_gives_the_records_of_the_process_pool(cluster, pool_records, tmp_path):
    assert cluster.workers == 2
    progress = io.StringIO()
    recs = ex.run_sweep(ex.tasks_for(ex.DECOUPLE, TRIALS, SEED), str(tmp_path / "results.jsonl"),
                        stream=progress, executor=cluster)
    assert [r["trial"] for r in recs] == list(range(TRIALS))
    assert [_same(r) for r in recs] == [_same(r) for r in pool_records]
    assert sum(r["success"] for r in recs) >= 1          # real trials ran (a failing decoupling still matches)
    assert "%d/%d" % (TRIALS, TRIALS) in progress.getvalue()


def test_a_sweep_started_on_the_pool_continues_on_the_cluster(cluster, pool_records, tmp_path):
    path = str(tmp_path / "results.jsonl")
    tasks = ex.tasks_for(ex.DECOUPLE, TRIALS, SEED)
    ex.run_sweep(tasks[:2], path, jobs=1, stream=io.StringIO())
    recs = ex.run_sweep(tasks, path, stream=io.StringIO(), executor=cluster)
    lines = [json.loads(s) for s in open(path)]
    assert [r["trial"] for r in lines[:2]] == [0, 1] and sorted(r["trial"] for r in lines[2:]) == [2, 3]
    assert [_same(r) for r in recs] == [_same(r) for r in pool_records]


def test_ordered_runs_keep_the_items_order_on_both_executors(cluster):
    items = [float(k) for k in range(12)]
    with executors.LocalPool(2) as pool:
        assert list(pool.run(math.sqrt, items, ordered=True)) == [math.sqrt(v) for v in items]
        assert sorted(pool.run(math.sqrt, items)) == [math.sqrt(v) for v in items]
    assert list(cluster.run(math.sqrt, items, ordered=True)) == [math.sqrt(v) for v in items]
    assert sorted(cluster.run(math.sqrt, items)) == [math.sqrt(v) for v in items]


def test_a_worker_with_other_code_or_configuration_is_refused(cluster):
    own = cluster.version
    cluster.version = "0000000000"          # what the command would hash after an edit the workers lack
    try:
        with pytest.raises(ConfigError, match="runs version %s" % own):
            list(cluster.run(math.sqrt, [1.0, 4.0]))
    finally:
        cluster.version = own
    assert list(cluster.run(math.sqrt, [4.0])) == [2.0]


def test_the_worker_setup_runs_once_per_worker_process(cluster):
    pids = set(cluster.run(_pid, range(8)))
    assert 1 <= len(pids) <= 2 and os.getpid() not in pids
    counts = list(cluster.run(_setups_seen, range(8), setup=_count_setup))
    assert all(n == 1 for n in counts), counts


_SETUPS = []


def _count_setup():
    _SETUPS.append(os.getpid())


def _setups_seen(_):
    return _SETUPS.count(os.getpid())


def _pid(_):
    return os.getpid()


def test_bad_cluster_options_are_refused_before_anything_starts():
    assert isinstance(executors.make_executor("", jobs=2), executors.LocalPool)
    for bad in ("local:0", "local:x", "node17"):
        with pytest.raises(ConfigError, match="--cluster"):
            executors.make_executor(bad)
    with pytest.raises(ConfigError, match="cannot reach"):
        executors.DaskCluster("tcp://127.0.0.1:9", connect_timeout=2)
