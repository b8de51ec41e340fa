"""Where a sweep's trials run: a local process pool (default) or a Dask cluster.

An executor runs a picklable function over picklable items and yields the
results as they come (``run``): the harness keeps each one in its results
file and advances its progress bar as it arrives, so a sweep is resumable and
shows progress whatever runs the trials. A trial's randomness comes from its
own seed (never from the process, the order or the time it runs in), so the
same tasks give the same records on every executor
(test_executors.py checks the process pool against a local Dask cluster).

``LocalPool(jobs, nice)``
    ``jobs`` forked worker processes on this machine (1: in this process).
``DaskCluster(address, nice)``
    The workers of a Dask distributed cluster: ``address`` is its scheduler
    (``tcp://HOST:8786``, started by ``dask scheduler``, workers by
    ``dask worker tcp://HOST:8786 --nworkers N --nthreads 1``), or
    ``local:N`` for a cluster of N worker processes started here and stopped
    on ``close`` (docs/results.md, Run). Every worker must run the same code
    and configuration as this process: each checks its own version
    (puzzlebot_experiments.version.config_hash) before its first trial and
    refuses to run any other, so results are never recorded under a version
    they were not computed with.

``make_executor(cluster, jobs, nice)`` picks one from the scripts'
``--cluster`` (``add_cluster_option``) and ``--jobs`` options. ``setup`` (a picklable callable, e.g. a
``functools.partial``) runs once in each worker process before its first item:
configuration every trial of that process shares.
"""

import logging
import multiprocessing
import os
from functools import partial

from puzzlebot_common.errors import ConfigError

#: ``--cluster`` prefix of a local Dask cluster started by the executor (``local:N``: N workers).
LOCAL_PREFIX = "local:"
#: Seconds to wait for a Dask scheduler to answer, and for the workers of a local cluster to start.
CONNECT_TIMEOUT_S = 60


def _renice(nice):
    if nice:
        try:
            os.nice(nice)
        except OSError:
            pass


def _pool_init(nice, setup):
    _renice(nice)
    if setup is not None:
        setup()


class LocalPool:
    """``jobs`` worker processes forked from this one (``jobs`` = 1: the items run in this process,
    ``nice`` not applied); ``nice``: niceness increment of the workers."""

    remote = False

    def __init__(self, jobs=None, nice=0):
        self.workers = max(1, int(jobs or os.cpu_count() or 1))
        self.nice = nice

    def describe(self):
        return "process pool of %d" % self.workers if self.workers > 1 else "this process"

    def run(self, fn, items, setup=None, ordered=False):
        """Yield ``fn(item)`` for every item: in ``items``' order if ``ordered``, else as each finishes."""
        items = list(items)
        if not items:
            return
        jobs = min(self.workers, len(items))
        if jobs == 1:
            if setup is not None:
                setup()
            for item in items:
                yield fn(item)
            return
        with multiprocessing.get_context("fork").Pool(jobs, initializer=_pool_init,
                                                        initargs=(self.nice, setup)) as pool:
            yield from (pool.imap if ordered else pool.imap_unordered)(fn, items)

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ------------------------------------------------------------------- Dask
#: Per worker process: the setups already run (by their pickled bytes) and the version checked.
_WORKER = {"setups": set(), "version": None}


def _on_worker(version, nice, setup, fn, item):
    """A task on a Dask worker: check the worker's version, renice and set up once, then ``fn(item)``."""
    if _WORKER["version"] is None:
        from puzzlebot_experiments.version import config_hash

        _WORKER["version"] = config_hash()
        _renice(nice)
    if _WORKER["version"] != version:
        raise ConfigError("worker %s runs version %s of the code and configuration, this sweep %s: start the "
                          "workers from the same checkout (built, same config) as the command"
                          % (os.uname().nodename, _WORKER["version"], version))
    if setup is not None:
        import pickle

        token = pickle.dumps(setup)
        if token not in _WORKER["setups"]:
            setup()
            _WORKER["setups"].add(token)
    return fn(item)


class DaskCluster:
    """The workers of a Dask distributed cluster (module docstring): ``address`` ``tcp://HOST:PORT`` of a
    running scheduler, or ``local:N`` to start N single-threaded worker processes here; ``nice``:
    niceness increment of the workers; ``connect_timeout`` [s]: for the scheduler to answer and (at
    least one, or the N local) workers to join."""

    remote = True

    def __init__(self, address, nice=0, connect_timeout=CONNECT_TIMEOUT_S):
        try:
            import distributed
        except ImportError as e:
            raise ConfigError("--cluster needs Dask distributed (requirements.txt; make setup installs it): %s"
                              % e) from None
        from puzzlebot_experiments.version import config_hash

        self.address, self.nice = address, nice
        self.version = config_hash()
        self._cluster = None
        try:
            if address.startswith(LOCAL_PREFIX):
                n = _local_workers(address)
                self._cluster = distributed.LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                    scheduler_port=0, silence_logs=logging.ERROR)
                self.client = distributed.Client(self._cluster, set_as_default=False, timeout=connect_timeout)
            else:
                self.client = distributed.Client(address, set_as_default=False, timeout=connect_timeout)
                n = 1
            self.client.wait_for_workers(n, timeout=connect_timeout)
        except (OSError, TimeoutError) as e:
            self.close()
            raise ConfigError("--cluster %s: cannot reach the Dask cluster: %s" % (address, e)) from None

    @property
    def workers(self):
        """Worker threads of the cluster now (each runs one trial at a time)."""
        return max(1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values()))

    def describe(self):
        info = self.client.scheduler_info()
        return "Dask cluster %s (%d workers, %d threads)" % (
            info.get("address", self.address), len(info["workers"]), self.workers)

    def run(self, fn, items, setup=None, ordered=False):
        """Yield ``fn(item)`` for every item (on the cluster's workers): in order if ``ordered``, else as
        each finishes. Tasks still queued are cancelled when the caller stops early (an error, Ctrl-C)."""
        import distributed

        items = list(items)
        if not items:
            return
        futures = self.client.map(partial(_on_worker, self.version, self.nice, setup, fn), items, pure=False)
        try:
            if ordered:
                for f in futures:
                    yield f.result()
                    f.release()
            else:
                for f in distributed.as_completed(futures, loop=self.client.loop):
                    yield f.result()
                    f.release()
        finally:
            self.client.cancel([f for f in futures if not f.done()])

    def close(self):
        client, cluster = getattr(self, "client", None), self._cluster
        self.client = self._cluster = None
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _local_workers(address):
    try:
        n = int(address[len(LOCAL_PREFIX):])
    except ValueError:
        n = 0
    if n < 1:
        raise ConfigError("--cluster %s: expected local:N with N >= 1 workers" % address)
    return n


def add_cluster_option(parser):
    """The scripts' ``--cluster ADDRESS`` option (argparse); ``make_executor`` reads it."""
    parser.add_argument("--cluster", default="", metavar="ADDRESS",
                        help="run the trials on a Dask cluster: its scheduler (tcp://HOST:8786), or local:N to "
                             "start N workers here (docs/results.md, Run; default: a local process pool of --jobs)")


def make_executor(cluster="", jobs=None, nice=0):
    """The executor of the scripts' options: ``cluster`` '' = LocalPool(jobs, nice); ``local:N`` or a
    scheduler address (``tcp://HOST:PORT``) = DaskCluster (``jobs`` then unused)."""
    cluster = (cluster or "").strip()
    if not cluster:
        return LocalPool(jobs, nice)
    if not (cluster.startswith(LOCAL_PREFIX) or "://" in cluster):
        raise ConfigError("--cluster %s: expected a scheduler address such as tcp://HOST:8786, or local:N"
                          % cluster)
    return DaskCluster(cluster, nice)
