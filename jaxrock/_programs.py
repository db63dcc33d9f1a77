"""Compiled chunk loops: made once per process and device, kept in jaxrock's
cache folder between processes."""

import contextlib
import json
import threading

import jax

from . import _cache, _layout
from ._chunk import map_chunk
from ._isolators import AbstractIsolator
from ._results import RESPONSE_FIELDS
from ._scene import MotionLayout
from ._xla import compiler_accepts

# The chunk loops of this process (see `chunk_program`), each made once: a
# map in another thread that needs a loop being made waits for it.
_PROGRAMS: dict = {}
_PROGRAM_LOCKS: dict = {}
_PROGRAMS_LOCK = threading.Lock()
# Tracing and lowering are Python, under the GIL: maps in threads take turns,
# and one traces while another compiles (XLA compiles without the GIL).
_TRACING = threading.Lock()
# Whether chunk loops compile for a first answer (`first_answer`).
_FIRST_ANSWER = False
# The most cells of a chunk on a base with a hysteretic state whose loop
# compiles at level 0 for a first answer: its compile takes about 2.5 s less
# on two cores, and its run under a record about 27 ms a cell more.
HYSTERETIC_LEVEL_0_CELLS = 64


@contextlib.contextmanager
def first_answer():
    """Within it, maps' chunk loops compile for a first answer: small maps
    whose compile is most of the wait, as the CLI's (the Python API keeps the
    defaults).

    They compile on the CPU at XLA's backend optimization level 0: in about
    half the time, to run 2.5-4 times as long (the docs' performance page,
    "Start-up"). On a base with a hysteretic state (a friction pendulum),
    whose analyses run long, only a chunk of at most
    `HYSTERETIC_LEVEL_0_CELLS` cells does (its run loses less than the
    compile saves); a larger one keeps XLA's level."""
    global _FIRST_ANSWER
    before, _FIRST_ANSWER = _FIRST_ANSWER, True
    try:
        yield
    finally:
        _FIRST_ANSWER = before


def chunk_program(treedef, leaves, loop: _layout.Loop):
    """`map_chunk` for a `ChunkTask` of the structure `treedef` (static fields
    included) and the shapes and device of `leaves` (jax Arrays), as `loop`,
    compiled: a function of the leaves that returns the
    responses' `RESPONSE_FIELDS`, the carries' leaves, and the lane-steps executed and
    useful.

    Made once per process and device. With jaxrock's cache folder
    (`_cache.program_folder`) and one local device, the compiled program is
    kept there, and a later process loads it instead of tracing, lowering and
    compiling again. A structure that names code outside jaxrock and its
    dependencies (a user's isolator class) is compiled in every process.
    """
    specs = tuple(
        jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding) for x in leaves
    )
    task = jax.tree_util.tree_unflatten(treedef, specs)
    platform = next(iter(leaves[0].devices())).platform
    cells = task.slenderness.shape[0]
    options = compiler_options(task.base, task.layout, _FIRST_ANSWER, platform, cells)
    key = (treedef, specs, loop, json.dumps(options))
    with _PROGRAMS_LOCK:
        lock = _PROGRAM_LOCKS.setdefault(key, threading.Lock())
    with lock:
        if key not in _PROGRAMS:
            _PROGRAMS[key] = _make_program(treedef, specs, loop, options, platform)
        return _PROGRAMS[key]


def _make_program(treedef, specs, loop: _layout.Loop, options: dict, platform: str):
    """`chunk_program`'s function, compiled here or loaded from the folder."""

    def map_chunk_program(*leaves):
        task = jax.tree_util.tree_unflatten(treedef, leaves)
        responses, carries, executed, useful = map_chunk(task, loop)
        fields = tuple(getattr(responses, f) for f in RESPONSE_FIELDS)
        return fields, tuple(jax.tree_util.tree_leaves(carries)), executed, useful

    traced = jax.jit(map_chunk_program, compiler_options=options)

    def lower():
        with _TRACING:
            return traced.lower(*specs)

    static = _cache.static_key(treedef)
    shapes = [(s.shape, str(s.dtype)) for s in specs]
    key = json.dumps([static, shapes, list(loop), options, platform])
    if static is None or len(jax.local_devices(backend=platform)) > 1:
        key = None  # not kept
    return _cache.compiled("map_chunk", key, lower, platform)


def compiler_options(
    base: AbstractIsolator,
    layout: MotionLayout,
    first_answer: bool = False,
    platform: str | None = None,
    cells: int | None = None,
) -> dict:
    """XLA's options for a chunk loop of `cells` cells (None: any number) on
    `base` under a motion laid out as `layout` (with `first_answer`: see
    `first_answer`) on `platform` (default: JAX's default backend).

    On the CPU, a loop under a closed-form motion on a base without a
    hysteretic state compiles with XLA's loop emitters instead of its fusion
    emitters: it compiles faster and runs about as fast, while records' reads
    of their samples and a friction pendulum's z run faster with the fusion
    emitters (the docs' performance page, "Choices in the code").
    (XLA releases without that option, jaxlib 0.11 on, keep their default.)
    """
    platform = platform or jax.default_backend()
    if platform != "cpu":
        return {}
    options = {}
    small = cells is not None and cells <= HYSTERETIC_LEVEL_0_CELLS
    if first_answer and (small or not base.hysteretic_state):
        options["xla_backend_optimization_level"] = 0
    if layout is MotionLayout.PER_CELL and not base.hysteretic_state:
        options["xla_cpu_use_fusion_emitters"] = False
    if not options or compiler_accepts(options, platform):
        return options
    return {k: v for k, v in options.items() if compiler_accepts({k: v}, platform)}
