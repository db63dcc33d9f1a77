"""XLA's CPU option that compiles a while loop as one kernel.

On the CPU, XLA compiles a program into kernels (each fused group of
operations) that its runtime dispatches one after the other: at a map's lane
width (128 lanes) a step of every lane is about a hundred small kernels, and
dispatching them costs as much as computing them. XLA compiles a while loop
whose buffers total less than `xla_cpu_small_while_loop_byte_threshold` bytes
(1 kB by default) as one kernel instead: its body runs as compiled code, with
no dispatch between its operations. jaxrock raises that size to 1 GB, so
that the loop that steps a map's lanes is one kernel (a loop holding a scatter
stays kernel by kernel: the step loop gathers, never scatters).

The option is process-wide and read when JAX starts its CPU backend, so it is
set at import, before any computation: importing jaxrock after JAX has
computed leaves it unset (maps run 1.2-2x slower, with the same results to
the last bits, except for a friction pendulum's z, whose rounding can differ).
"""

import os

# The environment variable that keeps XLA's default ("off", "0", "none",
# "false" or "no").
ENVIRONMENT = "JAXROCK_LOOP_KERNELS"
OPTION = "xla_cpu_small_while_loop_byte_threshold"
_BYTES = 1_000_000_000
_OFF = {"off", "0", "none", "false", "no"}


def compile_loops_whole() -> bool:
    """Add `--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1e9`
    to `XLA_FLAGS`, unless `XLA_FLAGS` sets XLA's backend options already (the
    user's choice), `JAXROCK_LOOP_KERNELS=off`, or JAX's backends have started
    (too late: the flags are read). Returns whether the option is in effect."""
    import jax._src.xla_bridge as xla_bridge

    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_extra_options" in flags:
        return OPTION in flags
    if os.environ.get(ENVIRONMENT, "").strip().lower() in _OFF:
        return False
    if xla_bridge.backends_are_initialized():
        return False
    option = f"--xla_backend_extra_options={OPTION}={_BYTES}"
    os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()
    return True
