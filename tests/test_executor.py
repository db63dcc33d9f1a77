"""Maps on an executor: each chunk one task, the map the same to the bit as
the local one (a Dask cluster of two worker processes, an in-process executor),
a lost worker's chunk computed again, a failed chunk named, a stored map
resumed without tasks."""

import os
import pickle
import sys
from concurrent.futures import Executor, Future

import jax
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _maps
from jaxrock.cli import main

LAM = np.array([1.5, 2.5, 3.5, 5.0, 6.5])
SIZE = np.array([0.3, 1.0, 2.5])
BASE = jr.LinearIsolator(2.0, 0.35, 0.5)
PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


def run_map(**options):
    """The map of the `linear_map` fixture (the same compile), with options."""
    return jr.behavior_map(LAM, SIZE, BASE, PULSE, chunk_size=4, **options)


def assert_same_map(bm, expected):
    for k in _maps._FIELDS + ("slenderness", "size"):
        np.testing.assert_array_equal(getattr(bm, k), getattr(expected, k), k)


class InProcess(Executor):
    """Runs each task at once in this thread, after a round trip of the task
    and its result through pickle, and checks that both are NumPy; counts
    the tasks, and fails the task numbered `fail` (from 0)."""

    def __init__(self, fail=None):
        self.submitted, self.fail = 0, fail

    def submit(self, fn, task):
        leaves = jax.tree_util.tree_leaves(task)
        assert leaves and all(isinstance(x, np.ndarray) for x in leaves)
        fn, task = pickle.loads(pickle.dumps((fn, task)))
        future, self.submitted = Future(), self.submitted + 1
        if self.submitted - 1 == self.fail:
            future.set_exception(OSError("worker lost"))
            return future
        out = pickle.loads(pickle.dumps(fn(task)))
        assert all(isinstance(x, np.ndarray) for x in jax.tree_util.tree_leaves(out))
        future.set_result(out)
        return future


def test_in_process_executor_and_a_failed_chunk(linear_map, tmp_path):
    """15 cells in chunks of 4: 2 chunks of pilots, then 4 of cells."""
    executor = InProcess()
    bm = run_map(executor=executor)
    assert_same_map(bm, linear_map)
    assert bm.lane_efficiency == linear_map.lane_efficiency
    assert executor.submitted == 6
    # The chunk of cells 1 fails: the error names it, the others are stored,
    # and a rerun computes it alone (after the pilots).
    with pytest.raises(RuntimeError, match="chunk 1 of the map failed.*worker lost"):
        run_map(executor=InProcess(fail=3), store=tmp_path)
    assert len(list(tmp_path.glob("chunk_*.npz"))) == 3
    again = InProcess()
    assert_same_map(run_map(executor=again, store=tmp_path), linear_map)
    assert again.submitted == 3
    with pytest.raises(ValueError, match="executor.*Executor"):
        run_map(executor="localhost:8786")


def test_cli_scheduler_without_dask(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "distributed", None)  # not installed
    argv = ["map", "--out", str(tmp_path / "m.png"), "--scheduler", "tcp://a:8786"]
    assert main(argv) == 2
    assert "--scheduler needs Dask" in capsys.readouterr().err


def die_once(flag, fn, task):
    """fn(task), but the first task of cells (pilot flag False) to find no
    `flag` file creates it and kills its worker process."""
    if not task.pilot:
        try:
            os.close(os.open(flag, os.O_CREAT | os.O_EXCL))
            os._exit(1)
        except FileExistsError:
            pass
    return fn(task)


class Through(Executor):
    """Submits to `inner`, counting the tasks, each through `die_once` if
    `flag` names a file."""

    def __init__(self, inner, flag=None):
        self.inner, self.flag, self.submitted = inner, flag, 0

    def submit(self, fn, task):
        self.submitted += 1
        if self.flag is None:
            return self.inner.submit(fn, task)
        return self.inner.submit(die_once, self.flag, fn, task)


@pytest.fixture(scope="module")
def cluster():
    """A Dask cluster of two worker processes; they inherit this process's
    environment, so its compilation cache (see conftest.py)."""
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield cluster, client


def test_cli_map_on_a_dask_scheduler(cluster, tmp_path, capsys):
    cluster, _ = cluster
    out = tmp_path / "bm.png"
    argv = ["map", "--base", "linear", "--no-compare", "--pulse", "San Fernando PCD/SN"]
    argv += ["--slenderness", "2:6:3", "--size", "0.5:2:2", "--chunk-size", "4"]
    assert (
        main(argv + ["--out", str(out), "--scheduler", cluster.scheduler_address]) == 0
    )
    on_cluster = jr.BehaviorMap.load(tmp_path / "bm_LinearIsolator.npz")
    local = jr.behavior_map([2.0, 4.0, 6.0], [0.5, 2.0], BASE, PULSE, chunk_size=4)
    for k in _maps._FIELDS:
        np.testing.assert_array_equal(getattr(on_cluster, k), getattr(local, k), k)


def test_dask_map_equals_local_survives_a_lost_worker_and_resumes(
    cluster, linear_map, tmp_path
):
    _, client = cluster
    flag = tmp_path / "killed"
    dying = Through(client.get_executor(), str(flag))
    store = tmp_path / "store"
    bm = run_map(executor=dying, store=store)
    assert_same_map(bm, linear_map)
    assert bm.lane_efficiency == linear_map.lane_efficiency
    assert flag.exists() and dying.submitted == 6  # a worker died; Dask reran its task
    assert len(list(store.glob("chunk_*.npz"))) == 4
    rerun = Through(client.get_executor())
    assert_same_map(run_map(executor=rerun, store=store), linear_map)
    assert rerun.submitted == 0  # every chunk read from the store
