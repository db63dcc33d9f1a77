import os
import tempfile

import matplotlib

matplotlib.use("Agg")
# Notebooks (run by tests/test_notebooks.py) take their small configuration.
os.environ.setdefault("JAXROCK_SMALL", "1")
# One XLA compilation cache for this run, shared by the xdist workers, the
# notebooks' kernels and the subprocesses (much of the suite's time is
# compiling): a fresh folder per run, so every run still compiles everything once.
_run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
os.environ.setdefault(
    "JAX_COMPILATION_CACHE_DIR",
    os.path.join(tempfile.gettempdir(), f"jaxrock-xla-cache-{_run}")
    if _run
    else tempfile.mkdtemp(prefix="jaxrock-xla-cache-"),
)
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jaxrock  # noqa: E402, F401
