import atexit
import os
import shutil
import tempfile

import matplotlib

matplotlib.use("Agg")
# Notebooks (run by tests/test_notebooks.py) take their small configuration.
os.environ.setdefault("JAXROCK_SMALL", "1")
# One XLA compilation cache for this run, shared with the subprocesses (CLI,
# devices): much of the suite's time is compiling. A fresh folder per run, so
# every run still compiles everything once; it is removed at the end.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
    _cache = tempfile.mkdtemp(prefix="jaxrock-xla-cache-")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = _cache
    atexit.register(shutil.rmtree, _cache, ignore_errors=True)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)


import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxrock as jr  # noqa: E402


@pytest.fixture(scope="session")
def linear_map():
    """The San Fernando map of a small grid on the paper's linear isolator, in
    chunks of 4 (the map tests, the store tests and the CLI compare with it)."""
    return jr.behavior_map(
        np.array([1.5, 2.5, 3.5, 5.0, 6.5]),
        np.array([0.3, 1.0, 2.5]),
        jr.LinearIsolator(2.0, 0.35, 0.5),
        jr.near_fault_pulse("San Fernando PCD/SN"),
        chunk_size=4,
        progress=False,
    )
