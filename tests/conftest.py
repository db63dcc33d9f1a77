import os
import tempfile

import matplotlib

matplotlib.use("Agg")
# Notebooks (run by tests/test_notebooks.py) take their small configuration.
os.environ.setdefault("JAXROCK_SMALL", "1")
# One XLA compilation cache for this run, shared with the subprocesses (CLI,
# devices): much of the suite's time is compiling. A fresh folder per run, so
# every run still compiles everything once.
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR", tempfile.mkdtemp(prefix="jaxrock-xla-cache-")
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jaxrock  # noqa: E402, F401
