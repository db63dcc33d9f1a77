import os

import matplotlib

matplotlib.use("Agg")
# Notebooks (run by nbmake) take their small configuration.
os.environ.setdefault("JAXROCK_SMALL", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jaxrock  # noqa: E402, F401
