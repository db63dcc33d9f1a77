"""Chunks of a map as the tasks of a `concurrent.futures.Executor`: a process
pool, a Dask cluster (`Client.get_executor()`), MPI (`MPIPoolExecutor`)."""

from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from contextlib import suppress


def check_executor(executor) -> None:
    """`ValueError` unless `executor` is None or a `concurrent.futures.Executor`
    (a `ProcessPoolExecutor` that starts its workers by forking this process
    is refused: JAX is multithreaded, and a forked worker deadlocks)."""
    if executor is None:
        return
    if not isinstance(executor, Executor):
        hint = ""
        if hasattr(executor, "get_executor"):  # a Dask Client
            hint = " (for a Dask Client, pass client.get_executor())"
        raise ValueError(
            "`executor` must be a concurrent.futures.Executor or None, got "
            f"{type(executor).__name__}{hint}"
        )
    context = getattr(executor, "_mp_context", None)
    if isinstance(executor, ProcessPoolExecutor) and context is not None:
        if context.get_start_method() == "fork":
            raise ValueError(
                "`executor`: a ProcessPoolExecutor that forks deadlocks under "
                "JAX; pass mp_context=multiprocessing.get_context('spawn')"
            )


def run_tasks(executor: Executor, fn, tasks: dict, what: str, done=None, bar=None):
    """fn(tasks[k]) for every k on `executor`, all submitted at once.

    As each result arrives (in any order) `done(k, result)` runs in this
    thread and the progress bar `bar` moves on. A task that fails, after any
    retries of the executor's own, raises `RuntimeError` naming the chunk
    (`what` k), once the tasks that have not started are cancelled and those
    running have ended (their results through `done`: a map's store keeps
    them).

    Returns:
        {k: result} for every k of `tasks`.
    """
    futures = {executor.submit(fn, task): k for k, task in tasks.items()}
    out = {}

    def collect(future):
        k = futures[future]
        try:
            result = future.result()
        except Exception as err:
            raise RuntimeError(
                f"{what} {k} of the map failed on the executor: "
                f"{type(err).__name__}: {err}"
            ) from err
        if done is not None:
            done(k, result)
        out[k] = result
        if bar is not None:
            bar.update(1)

    try:
        for future in as_completed(futures):
            collect(future)
    except BaseException as err:
        # Cancel the tasks not started; after a failed task (not an
        # interruption), keep what the running ones finish.
        running = [f for f in futures if not f.cancel() and futures[f] not in out]
        if isinstance(err, Exception):
            for future in running:
                with suppress(Exception):
                    collect(future)
        raise
    return out
