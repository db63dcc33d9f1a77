"""XLA's CPU option that compiles a while loop as one kernel.

On the CPU, XLA compiles a program into kernels (each fused group of
operations) that its runtime dispatches one after the other: at a map's lane
width (64 lanes) a step of every lane is about a hundred small kernels, and
dispatching them costs as much as computing them. A while loop that XLA's
cost model deems small (a pass of its body reads and writes fewer bytes than
`xla_cpu_small_while_loop_byte_threshold`, 1 kB by default) is compiled as
one kernel instead: its body runs as compiled code, with no dispatch between
its operations. jaxrock raises the threshold to 1e15 bytes, so that the loop
that steps a map's lanes is one kernel whatever its motion. (The cost model
counts the whole of an array at each read from it: a step under a suite of 28
records, which reads their 64 MB of tables of peaks several times, counts
more than 1 GB. A loop holding a scatter stays kernel by kernel: the step
loop gathers, never scatters.)

The option is process-wide and read when JAX starts its CPU backend, so it is
set at import, before any computation: importing jaxrock after JAX has
computed leaves it unset (with a warning), and maps run slower (the
same results, but for the last bits of a friction pendulum's z).

On a GPU, each pass of a `lax.while_loop` and each `lax.cond` of a program
waits for its predicate to reach the host before the next kernel starts.
With XLA's command buffers for WHILE and CONDITIONAL (`GPU_GRAPHS`, also set
at import), such control flow runs on the device as CUDA graphs: a map's
loop, its step loop and the conditionals of its event batches. The maps are
the same, bit for bit, and run in 0.81-0.95 of the time (the documentation's
performance page, "On a GPU").

`JAXROCK_LOOP_KERNELS=flattened` adds XLA's `xla_cpu_flatten_after_fusion`:
the fused groups of a kernel are inlined into it, and the compiler optimizes
across them. The friction pendulum's record maps then run faster, the
others about as fast, and every map compiles several times longer (the
documentation's performance page, "One kernel a loop"): for long campaigns
of friction-pendulum maps, whose compiled loops the cache folder keeps.
"""

import functools
import json
import os
import warnings

import jax

from ._misc import turned_off

# The environment variable that keeps XLA's default (`turned_off`), or with
# FLATTENED adds `FLATTEN`.
ENVIRONMENT = "JAXROCK_LOOP_KERNELS"
FLATTENED = "flattened"
OPTION = "xla_cpu_small_while_loop_byte_threshold"
FLATTEN = "xla_cpu_flatten_after_fusion"
_BYTES = 10**15
COMMAND_BUFFERS = "xla_gpu_enable_command_buffer"
GPU_GRAPHS = f"--{COMMAND_BUFFERS}=+WHILE,+CONDITIONAL"


def compile_loops_whole() -> bool:
    """Add `--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=
    1000000000000000` to `XLA_FLAGS`, unless `XLA_FLAGS` sets XLA's backend
    options already (the user's choice), `JAXROCK_LOOP_KERNELS=off`, or JAX's
    backends have started (too late: the flags are read; a `RuntimeWarning`
    says so); with `JAXROCK_LOOP_KERNELS=flattened`, `,xla_cpu_flatten_after_
    fusion` too. Returns whether the option is in effect."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_extra_options" in flags:
        return OPTION in flags
    setting = os.environ.get(ENVIRONMENT, "")
    if turned_off(setting):
        return False
    if _backends_started():
        warnings.warn(
            "jaxrock was imported after JAX started its backends, too late to "
            f"compile loops as one kernel ({OPTION}): behavior maps run "
            "slower. Import jaxrock before JAX computes anything, or set "
            f"{ENVIRONMENT}=off to keep XLA's default without this warning.",
            RuntimeWarning,
            stacklevel=2,
        )
        return False
    option = f"--xla_backend_extra_options={OPTION}={_BYTES}"
    if setting.strip().lower() == FLATTENED:
        option += f",{FLATTEN}"
    os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()
    return True


def control_flow_as_gpu_graphs() -> bool:
    """Add `GPU_GRAPHS` to `XLA_FLAGS`, unless `XLA_FLAGS` sets XLA's command
    buffers already (the user's choice) or JAX's backends have started (the
    flags are read). Returns whether the flag is in effect. (On a CPU, XLA
    reads and ignores it.)"""
    flags = os.environ.get("XLA_FLAGS", "")
    if COMMAND_BUFFERS in flags:
        return GPU_GRAPHS in flags
    if _backends_started():
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {GPU_GRAPHS}".strip()
    return True


def _backends_started() -> bool:
    """Whether JAX has started its backends (read from a private JAX module:
    False where a JAX release moved it, and the flags are set regardless)."""
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except (ImportError, AttributeError):
        return False


def compiler_accepts(options: dict, platform: str | None = None) -> bool:
    """Whether this JAX's XLA on `platform` (default: the default backend)
    takes the compiler `options`: XLA adds and removes options between
    releases, and refuses a program with one it does not know."""
    return _accepts(json.dumps(options, sort_keys=True), platform)


@functools.cache
def _accepts(options: str, platform: str | None) -> bool:
    program = jax.jit(lambda x: x + 1.0, compiler_options=json.loads(options))
    device = jax.local_devices(backend=platform)[0]
    try:
        program.lower(jax.device_put(1.0, device)).compile()
    except jax.errors.JaxRuntimeError:
        return False
    return True
