"""Behavior maps: one analysis per (slenderness, size) cell, in chunks run on
the local devices or as an executor's tasks.

The concepts live apart: the grid and its cells (`_grid.py`), the in-device
chunk loop (`_chunk.py`), its compiled programs (`_programs.py`), the result
and its files (`_behavior_map.py`); this module plans the chunks, runs them
and assembles the map.
"""

import os
import time
from collections.abc import Sequence
from concurrent.futures import Executor, ThreadPoolExecutor

import equinox as eqx
import jax
import numpy as np

from . import _layout
from ._behavior_map import BehaviorMap, check_chunk, check_counts
from ._block import Block
from ._chunk import ChunkTask
from ._dynamics import check_restitution
from ._executor import check_executor, run_tasks
from ._grid import Grid, check_fits_in_memory
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator, describe_base
from ._labeled import coordinates
from ._misc import as_float, broadcast_batch_shape, grid_axis
from ._model import check_base_and_motion
from ._programs import chunk_program
from ._results import (
    ATOL,
    MAX_SEGMENTS,
    RESPONSE_FIELDS,
    REST_TOLERANCE,
    RTOL,
    SolverOptions,
)
from ._scene import MotionLayout
from ._store import ChunkStore

_FIELDS = RESPONSE_FIELDS


def _numpy(tree):
    """The pytree with its JAX arrays as NumPy arrays (picklable: a task's)."""
    return jax.tree_util.tree_map(
        lambda x: np.asarray(x) if isinstance(x, jax.Array) else x, tree
    )


def _on_device(task: ChunkTask, device) -> ChunkTask:
    """The task's arrays on `device` (its options' arrays only: their other
    leaves are Python values the program reads as constants)."""
    opts = jax.tree_util.tree_map(
        lambda x: jax.device_put(x, device) if isinstance(x, np.ndarray) else x,
        task.opts,
    )
    arrays = jax.device_put(eqx.tree_at(lambda t: t.opts, task, None), device)
    return eqx.tree_at(lambda t: t.opts, arrays, opts, is_leaf=lambda x: x is None)


def _compute_chunk(task: ChunkTask, device=None) -> dict:
    """One chunk of a map: the task `behavior_map` gives an executor.

    `task` holds NumPy arrays (`_ChunkRunner.task`); they go to `device`
    (default: the first local device). Returns NumPy arrays: for a chunk of
    cells its `_FIELDS`, for a chunk of pilots the leaves of their carries
    ("carries", a list), each for the chunk's cells only (not its padding);
    and the lane-steps executed and those that advanced an analysis
    ("executed", "useful").
    """
    device = device or jax.local_devices()[0]
    leaves, treedef = jax.tree_util.tree_flatten(_on_device(task, device))
    program = chunk_program(treedef, leaves, _layout.loop_for(device.platform))
    fields, carries, executed, useful = jax.device_get(program(*leaves))
    count = int(task.count)
    if bool(task.pilot):
        out = {"carries": [x[:count] for x in carries]}
    else:
        out = {f: np.asarray(x)[:count] for f, x in zip(_FIELDS, fields)}
    return out | {"executed": np.asarray(executed), "useful": np.asarray(useful)}


class _ChunkRunner:
    """Runs chunks of cells through `map_chunk` (`_compute_chunk`), on
    `devices` or as the tasks of an executor.

    A chunk's cells are padded to `padded` (the last cell repeated, never
    analysed) so that maps of other sizes reuse a handful of compiles. Without
    an executor, chunks go round-robin to `devices` (GPUs, or the CPU: one
    device, or several with
    XLA_FLAGS=--xla_force_host_platform_device_count=N), from one thread per
    CPU core: XLA releases the GIL, so chunks run at once.
    """

    def __init__(self, grid: Grid, duration, opts, padded: int, devices, executor=None):
        self.grid, self.padded, self.executor = grid, padded, executor
        self.motion, self.duration, self.opts = _numpy(
            (grid.motion.unlabeled(), duration, opts)
        )
        self.one_base = _numpy(grid.base) if grid.base_shape == () else None
        self.devices = devices
        # A thread per CPU core, or per accelerator (each runs its chunks in turn).
        cpu = self.devices[0].platform == "cpu"
        self.threads = len(self.devices)
        if cpu:
            self.threads = max(self.threads, os.cpu_count() or 1)

    def task(self, index, inputs, shared, pilot) -> ChunkTask:
        """The cells `index` of `inputs` and `shared`, as NumPy: a task of
        `_compute_chunk`."""
        count = index.size
        take = np.pad(index, (0, self.padded - count), mode="edge")

        def part(tree):
            return jax.tree_util.tree_map(lambda x: np.asarray(x)[take], tree)

        lam_k, r_k, base_k, motion_k, own_k = inputs
        layout = self.grid.layout
        per_cell = layout is MotionLayout.PER_CELL
        return ChunkTask(
            slenderness=part(lam_k),
            size=part(r_k),
            base=part(base_k),
            motion=part(motion_k) if per_cell else self.motion,
            suite_index=part(motion_k) if layout is MotionLayout.SUITE else None,
            own=part(own_k),
            shared=part(shared),
            one_base=self.one_base,
            duration=self.duration,
            opts=self.opts,
            count=np.asarray(count),
            pilot=np.asarray(pilot),
            layout=layout,
        )

    def device(self, k):
        """Chunk k's local device (round-robin)."""
        return self.devices[k % len(self.devices)]

    def run(self, jobs, inputs, shared, pilot, done=None, bar=None) -> dict:
        """The chunks `jobs` ({k: its cells}) of pass 1 (`pilot`) or 2 of the
        cells `inputs` and `shared`: {k: `_compute_chunk`'s result}, and
        done(k, result) as each ends; the progress bar `bar` counts them.

        On the executor, if any (`run_tasks`); else round-robin over the local
        devices from one thread per CPU core (the first chunk of a device
        compiles its loop, the others wait for it).
        """

        def task(k):
            return self.task(jobs[k], inputs, shared, pilot)

        if self.executor is not None:
            what = "pilot chunk" if pilot else "chunk"
            tasks = {k: task(k) for k in jobs}
            return run_tasks(self.executor, _compute_chunk, tasks, what, done, bar)

        def compute(k):
            out = _compute_chunk(task(k), self.device(k))
            if done is not None:
                done(k, out)
            return out

        out = {}
        with ThreadPoolExecutor(self.threads) as pool:
            for k, result in zip(jobs, pool.map(compute, jobs)):
                out[k] = result
                if bar is not None:
                    bar.update(1)
        return out


def _run_pilots(runner: _ChunkRunner, grid: Grid, chunk: int):
    """Pass 1: the pilots, from t = 0 to where their cells part ways, `chunk`
    at a time. Returns every cell's start (its pilot's carry) and the pilots'
    useful and executed lane-steps."""
    blank = grid.blank_carries()
    pilots = range(0, grid.pilots, chunk)
    pilots = {
        k: np.arange(i, min(i + chunk, grid.pilots)) for k, i in enumerate(pilots)
    }
    done = runner.run(pilots, grid.pilot_inputs, blank, True)
    leaves = zip(*(done[k]["carries"] for k in range(len(done))))
    carries = jax.tree_util.tree_unflatten(
        jax.tree_util.tree_structure(blank), map(np.concatenate, leaves)
    )
    starts = jax.tree_util.tree_map(lambda x: x[grid.pilot_of_cell], carries)
    useful = sum(int(d["useful"]) for d in done.values())
    executed = sum(int(d["executed"]) for d in done.values())
    return starts, useful, executed


def behavior_map(
    slenderness,
    size,
    base: AbstractIsolator,
    motion: AbstractGroundMotion,
    *,
    duration: float | None = None,
    rtol: float = RTOL,
    atol: float = ATOL,
    chunk_size: int | str | None = "auto",
    progress: bool | None = None,
    max_segments: int = MAX_SEGMENTS,
    max_steps: int | None = None,
    rest_tolerance: float = REST_TOLERANCE,
    solver=None,
    store: str | os.PathLike | None = None,
    executor: Executor | None = None,
    devices: Sequence[jax.Device] | None = None,
    restitution_factor=None,
    restitution=None,
    friction: float | None = None,
) -> "BehaviorMap":
    """Classify every block of the grid `slenderness` x `size` (1-D arrays).

    Every cell is the exact analysis of `simulate` (without a `duration`:
    until the block's fate is decided, at most `DECISION_WINDOW` s after the
    end of the cell's own motion, as under it alone); on a fixed base the free
    rocking after the excitation is finished in closed form (`_free.py`: the
    same apexes, impacts, rest rule and segments, without steps; `steps`
    counts the integrated part). The parameters of `base` and
    of an `MPPulse` may carry batch axes (an ensemble of isolators or of pulses,
    e.g. `LinearIsolator(period=jnp.array([1.5, 2.0, 2.5]), ...)`): the result
    then has shape base batch + pulse batch + (n_slenderness, n_size).
    Cells run `chunk_size` at a time (`None`: all at once; "auto", the
    default: 610 with a store or an executor, else as few chunks as keep the
    devices busy: on a CPU a multiple of its cores, of at most 8,192 cells
    each; on a GPU one chunk per GPU of up to 1,048,576 cells) through one
    compiled loop on vmapped lanes (64 on a CPU, 131,072 on a GPU); each
    iteration advances every lane by one solver step, and a lane that
    finishes takes the chunk's next cell (the "flat loop", `_flat.py`). The
    pure-translation phase before uplift runs once per base, motion and
    slenderness (see `_chunk.map_chunk`), and the cells, ordered by where that
    leaves them, are dealt to the chunks in turn (equal work per chunk).
    Chunks run one thread per CPU core, or per GPU.
    `progress` shows a tqdm bar (default: when there is more than one chunk).
    New grids, pulses or isolator parameters reuse the compile.

    `restitution_factor` (f > 0, the coefficient applied at a re-uplift
    e = f e_0) or `restitution` (e itself, in [0, 1]), as `Block` takes
    them: one value for every block, or a 1-D array of values that adds an
    axis after the motions' (`coordinates` name it); default the momentum
    model's e_0. f e_0 <= 1 is checked for every slenderness of the grid.
    `friction` (mu > 0, one number) checks every block for sliding, as
    `Block` does: a cell whose block would slide is `Status.SLIDING`.

    `store=DIR` writes each finished chunk to DIR (resumable: a rerun computes
    only the missing chunks, dealt the cells as the first run dealt them; a
    damaged chunk is computed again, with a `RuntimeWarning` naming it).

    `executor`, a `concurrent.futures.Executor` (a `ProcessPoolExecutor`, a
    Dask cluster's `Client.get_executor()`, an `mpi4py.futures.MPIPoolExecutor`),
    runs every chunk as one task instead of the local threads: the task
    (`_compute_chunk`) takes and returns NumPy arrays. The pilots (the shared
    phase, one chunk per `chunk_size` of them) run as tasks first, then the
    chunks of cells; each result goes to the store as it arrives, and a task
    that fails (after the executor's own retries) raises `RuntimeError` naming
    its chunk. The map is the same to the bit as without an executor.

    `devices` (JAX devices of one platform, e.g. `jax.devices("cpu")`) run
    the chunks without an executor. Default: the local devices, but the
    host's CPU for a map of at most 16,384 cells where the local devices are
    GPUs (such a map runs faster there, and compiles in a few seconds rather
    than tens: the docs' performance page, "On a GPU").
    """
    check_base_and_motion(base, motion)
    check_executor(executor)
    devices = _devices(devices, executor)
    lam, r = grid_axis("slenderness", slenderness), grid_axis("size", size)
    Block(lam, 1.0), Block(1.0, r)  # the ranges of each axis
    duration, opts = SolverOptions.for_analysis(
        motion,
        duration,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        max_segments=max_segments,
        rest_tolerance=rest_tolerance,
        solver=solver,
    )
    own = _restitution(restitution_factor, restitution, lam, base)
    friction = _friction(friction)
    grid = _checked_grid(lam, r, base, motion, own, friction)
    devices, plan = _plan(grid, chunk_size, devices, store, executor)
    duration = as_float(duration)
    runner = _ChunkRunner(grid, duration, opts, plan[1], devices, executor)
    return _computed(runner, grid, plan, store, progress, duration, opts)


def _plan(grid: Grid, chunk_size, devices, store, executor):
    """The devices that run the map's chunks (given, or by default
    `_layout.map_devices`; an executor's: the local ones, as its workers'),
    and its chunk plan, (cells a chunk, padded, chunks)."""
    units = store is not None or executor is not None  # chunks kept or sent out
    chunk_size = _layout.chunk_size(chunk_size, units)
    if devices is None:
        devices = jax.local_devices() if executor else _layout.map_devices(grid.n)
    return devices, _layout.chunk_plan(grid.n, chunk_size, devices)


def _computed(runner, grid: Grid, plan, store, progress, duration, opts):
    """The map: its chunks run (those of `store` read back) and assembled."""
    chunk, _, chunks = plan
    if store is not None:
        key = grid.store_key(duration, chunk, opts)
        store = ChunkStore(store, key, _FIELDS + ("index", "executed", "useful"))
    if progress is None:
        progress = chunks > 1
    t = time.perf_counter()
    results, useful, executed = _run(runner, grid, chunk, chunks, store, progress)
    return _assemble(grid, results, time.perf_counter() - t, useful, executed)


def _devices(devices, executor) -> list | None:
    """`devices` as a list, or None; `ValueError` unless it is None or a
    non-empty sequence of JAX devices of one platform, given without an
    `executor` (whose tasks run on its workers' devices)."""
    if devices is None:
        return None
    listed = list(devices) if isinstance(devices, (list, tuple)) else [devices]
    if not listed or not all(isinstance(d, jax.Device) for d in listed):
        raise ValueError(
            "`devices` must be None or a list of JAX devices, e.g. "
            f"jax.devices('cpu'), got {devices!r}"
        )
    if len({d.platform for d in listed}) > 1:
        raise ValueError(
            f"`devices` must be of one platform, got {[str(d) for d in listed]}"
        )
    if executor is not None:
        raise ValueError(
            "`devices` and `executor` exclude each other: an executor's chunks "
            "run on its workers' devices"
        )
    return listed


def _checked_grid(lam, r, base, motion, own, friction) -> Grid:
    """The map's `Grid`, once it is known to fit in this machine's memory."""
    shape = broadcast_batch_shape(base) + motion.batch_shape + (lam.size, r.size)
    blocks = 1 if own is None else np.size(own[1])
    check_fits_in_memory(int(np.prod(shape)) * blocks)
    return Grid(lam, r, base, motion, own, friction)


def _friction(friction) -> float | None:
    """The blocks' coefficient of friction for `Grid`: None, or one number
    in its range (`Block`)."""
    if friction is None:
        return None
    if np.ndim(friction) != 0:
        raise ValueError(
            f"`friction` must be one number, got shape {np.shape(friction)}"
        )
    Block(1.0, 1.0, friction=friction)
    return float(friction)


def _run(runner: "_ChunkRunner", grid: Grid, chunk: int, chunks: int, store, progress):
    """Every chunk's results, in order, and the pilots' useful and executed
    lane-steps: the chunks an earlier run left in `store` (and its pilots'
    counts, once all are there), the pilots (pass 1) and the missing chunks
    of cells (pass 2), each written to `store` as it ends."""
    results, counts = ({}, None) if store is None else _stored(store, grid, chunks)
    bar = _progress_bar(progress, chunks, len(results), type(grid.base).__name__)
    if counts is None:
        starts, useful, executed = _run_pilots(runner, grid, chunk)
        if store is not None:  # for `lane_efficiency` of a map read back whole
            store.write("pilots", dict(useful=useful, executed=executed))
        results |= _run_cells(runner, grid, starts, chunks, results, store, bar)
    else:  # every chunk from the store
        useful, executed = counts
    if bar is not None:
        bar.close()
    return [results[k] for k in range(chunks)], useful, executed


def _restitution(factor, coefficient, lam, base):
    """The blocks' own coefficient of restitution for `Grid`: None, or (the
    `Block` keyword, its values as a float array of 0 or 1 dimensions),
    checked: in range (`Block`), and f e_0 <= 1 for every slenderness of the
    grid on `base` (one without batch axes; an ensemble's cells check it in
    compiled code: `Status.INVALID_INPUT`)."""
    if factor is None and coefficient is None:
        return None
    name = "restitution_factor" if coefficient is None else "restitution"
    values = np.asarray(factor if coefficient is None else coefficient)
    if values.ndim > 1 or values.size == 0:
        raise ValueError(
            f"`{name}` must be one number or a 1-D array of numbers, got shape "
            f"{values.shape}"
        )
    # The ranges, and that only one of the two is given (`Block`).
    Block(1.0, 1.0, restitution_factor=factor, restitution=coefficient)
    if coefficient is None and broadcast_batch_shape(base) == ():
        check_restitution(
            Block(lam[:, None], 1.0, restitution_factor=values.reshape(1, -1)), base
        )
    return name, values.astype(float)


def _stored(store: ChunkStore, grid: Grid, chunks: int):
    """What an earlier run left in `store`: {k: chunk k} of the chunks whose
    arrays agree (`check_chunk`; with the order stored, chunk k holds the
    cells it deals chunk k), and the pilots' lane-step counts (useful,
    executed) if every chunk, the order and the counts are there, else None
    (the pilots run again)."""
    order = store.order(grid.n)

    def check(k, arrays):
        check_chunk(arrays, None if order is None else order[k::chunks])

    results = store.chunks(chunks, check)
    if len(results) < chunks or order is None:
        return results, None
    pilots = store.read("pilots", ("useful", "executed"), check_counts)
    if pilots is None:
        return results, None
    return results, (int(pilots["useful"]), int(pilots["executed"]))


def _progress_bar(progress: bool, chunks: int, done: int, base: str):
    """A tqdm bar over the chunks (`done` of them from a store) of a map on
    `base` (the name it shows: maps in threads each have a bar), or None."""
    if not progress:
        return None
    from tqdm.auto import tqdm

    desc = f"behavior map, {base}"
    return tqdm(total=chunks, initial=done, desc=desc, unit="chunk")


def _run_cells(runner: _ChunkRunner, grid: Grid, starts, chunks, done, store, bar):
    """Pass 2: the cells from their starts (`_run_pilots`), dealt to `chunks`
    chunks, but those `done` (from a store); each finished chunk goes to the
    store. Returns the new chunks' results."""
    # Cells by start time (the most work first), dealt to the chunks in turn:
    # chunks of equal work, and short analyses fill each one's tail. A store
    # keeps its first run's order: a rerun whose pilots differ in their last
    # bits (other hardware) deals the same chunks; one whose order was lost
    # deals them anew, and a stored chunk dealt otherwise is computed again.
    order = np.argsort(starts.t, kind="stable")
    if store is not None:
        order = store.dealt(order)
        same = {k: np.array_equal(done[k]["index"], order[k::chunks]) for k in done}
        for k in (k for k in done if not same[k]):
            store.damaged(store.path(k), "its cells are not those its order deals it")
        done = {k: c for k, c in done.items() if same[k]}
    cells = {k: order[k::chunks] for k in range(chunks) if k not in done}

    def finished(k, out):
        """Chunk k: its cells ("index") join its results."""
        out["index"] = cells[k]
        if store is not None:
            store.write(k, out)

    return runner.run(cells, grid.cell_inputs, starts, False, finished, bar)


def _assemble(grid: Grid, results, seconds, useful, executed) -> BehaviorMap:
    """The map from its chunks' results, in grid order."""
    index = np.concatenate([c["index"] for c in results])
    if not np.array_equal(np.sort(index), np.arange(grid.n)):
        raise RuntimeError(
            "the chunks do not hold every cell exactly once (a store whose "
            "chunks were dealt differently?)"
        )
    cell_order = np.argsort(index)
    fields = {
        f: np.concatenate([c[f] for c in results])[cell_order].reshape(grid.shape)
        for f in _FIELDS
    }
    useful += sum(int(c["useful"]) for c in results)
    executed += sum(int(c["executed"]) for c in results)
    return BehaviorMap(
        slenderness=grid.lam,
        size=grid.r,
        **fields,
        base=describe_base(grid.base),
        motion=grid.motion.describe(),
        seconds=seconds,
        lane_efficiency=useful / max(executed, 1),
        motion_names=grid.motion_names,
        coordinates=coordinates(grid.base, grid.motion, grid.restitution),
    )
