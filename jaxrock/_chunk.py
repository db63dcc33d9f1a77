"""The in-device loop of a map's chunk: vmapped lanes that refill from a queue
of cells, each advanced by one step attempt per iteration (`_flat.py`)."""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from . import _layout
from ._block import Block
from ._dynamics import Phase
from ._flat import flat_step
from ._free import free_rocking, free_rocking_ready
from ._isolators import AbstractIsolator
from ._misc import where_lanes
from ._model import (
    Carry,
    initial_carry,
    is_active,
    lane_window,
    response,
    with_start_conditions,
)
from ._results import SolverOptions, Status
from ._scene import MotionLayout, closed_form_tail, prepare
from ._signal import AbstractSignal

# The name scope of the loop that steps a chunk's lanes (`_Chunk.steps`): on
# the CPU, XLA compiles it as one kernel (see `_xla.py`).
STEP_LOOP = "lane_steps"


class _Lanes(eqx.Module):
    """The state of a chunk's loop: each lane's carry, cell (n: idle) and
    inputs, the queue's next cell, the results written so far (one per cell),
    the lanes that finished in the last steps, and the lane-steps executed and
    those that advanced an analysis."""

    carry: Carry
    cell: jax.Array
    queue: jax.Array
    out: Carry
    executed: jax.Array
    useful: jax.Array
    per_lane: tuple
    finished: jax.Array


class ChunkTask(eqx.Module):
    """A chunk of a map: what `map_chunk` takes but its loop, and what an
    executor's task carries (NumPy arrays, or JAX arrays on a device).

    `slenderness`, `size`, every leaf of `base` and of `shared` carry one
    leading cell axis. The motion is laid out as `layout` says: per cell
    (`motion`'s leaves carry the cell axis), one record of every cell, or a
    suite of records of which `suite_index` gives each cell's record (else
    None). `one_base` is the base of every cell without the cell axis, if
    they share one (else None: an ensemble of bases). `shared`: the carries
    the cells start from (their pilots'); `pilot`: a pass of pilots (see
    `map_chunk`). `own`: the cells' own `Block` keywords
    (`restitution_factor` or `restitution`, `friction`: a dict of per-cell
    arrays), or None for none. Cells from `count` on are
    padding and never analysed.
    """

    slenderness: Any
    size: Any
    base: Any
    motion: Any
    suite_index: Any
    own: Any
    shared: Any
    one_base: Any
    duration: Any
    opts: Any
    count: Any
    pilot: Any
    layout: MotionLayout = eqx.field(static=True)


@eqx.filter_jit
def map_chunk(task: ChunkTask, loop: _layout.Loop):
    """Analyse the first `task.count` cells of a chunk on `loop.lanes` lanes
    that refill from a queue (`count` is traced: one compile per chunk
    shape). Each iteration of the vmapped loop advances every lane by one step
    attempt (`flat_step`); a lane whose analysis is done writes its result and
    takes the chunk's next cell at once, so lanes wait for each other only at
    the chunk's end. (An inner loop steps the lanes until one finishes and the
    outer one refills: no `lax.cond` in every step, whose outputs XLA copies.)

    The pure-translation phase is shared (see `behavior_map`): until it uplifts a
    block moves with its base as one body, and neither the steps nor the events
    of that phase depend on the block. With `pilot` (traced: the same compile)
    each cell runs from t = 0 only up to the attempt in which it uplifts, or that
    reaches the end of the shaking or ends the analysis, and returns its carry
    before that attempt. Without, each cell starts from `shared` (such a carry
    of a pilot of its slenderness, base and motion), or from t = 0 if it
    uplifts at once, and redoes that attempt itself: the same steps as its
    own analysis from t = 0.

    On a base whose free rocking has a closed form (a fixed base), a lane that
    rocks once the ground is still (below the separatrix, on the near side of
    its corner) finishes at once; after the loop `free_rocking` completes all
    such cells of the chunk together.

    Returns the responses and carries (one per cell), the lane-steps executed
    (iterations times lanes) and those that advanced an analysis.
    """
    # The scene's signal, with the tables of its shortcuts (a record's peaks;
    # a linear isolator's response to it, for the base of every cell).
    signal = prepare(task.motion, task.one_base)
    chunk = _Chunk(
        task.slenderness,
        task.size,
        task.base,
        signal,
        task.suite_index,
        task.own,
        task.shared,
        task.duration,
        task.opts,
        task.pilot,
        task.layout,
        loop,
    )
    n, width = chunk.n, min(loop.lanes, chunk.n)
    # Every lane starts idle and finished: the loop's first `refill` gives
    # them the first cells.
    idle = jnp.full(width, n)
    per_lane0 = _zeros_of(chunk.gather, idle)
    carry0 = _zeros_of(chunk.start, idle, per_lane0)
    zero = jnp.asarray(0)
    state = _Lanes(
        carry=carry0,
        cell=idle,
        queue=zero,
        out=jax.tree_util.tree_map(
            lambda x: jnp.zeros((n,) + x.shape[1:], x.dtype), carry0
        ),
        executed=zero,
        useful=zero,
        per_lane=per_lane0,
        finished=jnp.ones(width, dtype=bool),
    )
    count = task.count
    state = jax.lax.while_loop(
        lambda s: jnp.any(s.cell < n) | (s.queue < count),
        lambda s: chunk.steps(chunk.refill(s, count)),
        state,
    )
    return (*chunk.responses(state.out), state.executed, state.useful)


def _zeros_of(f, *args):
    """Zeros shaped as the output of f(*args), which is traced, not computed."""
    return jax.tree_util.tree_map(
        lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(f, *args)
    )


class _Chunk(eqx.Module):
    """A chunk's cells and what its lanes share (a `ChunkTask` with its
    motion's signal), and the steps of its loop. The lanes read one record
    or a suite in place (a suite's lane holds its row, `RecordSignal.row`)."""

    slenderness: jax.Array
    size: jax.Array
    base: AbstractIsolator
    motion: AbstractSignal
    suite_index: jax.Array | None
    block_keywords: dict | None
    shared: Carry
    duration: jax.Array
    opts: SolverOptions
    pilot: jax.Array
    layout: MotionLayout = eqx.field(static=True)
    loop: _layout.Loop = eqx.field(static=True)

    @property
    def n(self) -> int:
        return self.slenderness.shape[0]

    @property
    def axes(self) -> tuple:
        """The `jax.vmap` in_axes of a lane's (block, base, motion)."""
        if self.layout is MotionLayout.SUITE:
            return 0, 0, self.motion.row_axes()
        return 0, 0, None if self.layout is MotionLayout.ONE_RECORD else 0

    def gather(self, cell):
        """The cells' block, base and motion, each with a lane axis (the motion
        None for one motion of every lane, the suite's rows for a suite: see
        `inputs`)."""
        cell = jnp.minimum(cell, self.n - 1)
        take = lambda tree: jax.tree_util.tree_map(lambda x: x[cell], tree)  # noqa: E731
        lane_motion = None
        if self.layout is MotionLayout.SUITE:
            lane_motion = self.suite_index[cell]
        elif self.layout is MotionLayout.PER_CELL:
            lane_motion = take(self.motion)
        return (
            Block(self.slenderness[cell], self.size[cell], **take(self.own)),
            take(self.base),
            lane_motion,
        )

    @property
    def own(self) -> dict:
        """The cells' own `Block` keywords (restitution, friction)."""
        return {} if self.block_keywords is None else self.block_keywords

    def inputs(self, per_lane):
        """`gather`'s output as `flat_step` takes it (batched as `axes` says)."""
        block, lane_base, lane_motion = per_lane
        if self.layout is MotionLayout.SUITE:
            return block, lane_base, self.motion.row(lane_motion)
        if self.layout is MotionLayout.ONE_RECORD:
            return block, lane_base, self.motion
        return block, lane_base, lane_motion

    def start(self, cell, per_lane):
        """The lanes' first carries: from t = 0 (pilots, or a cell that uplifts
        at once) or from their pilot's carry (`shared`); idle lanes done."""
        c = jax.vmap(initial_carry, in_axes=self.axes)(*self.inputs(per_lane))
        index = jnp.minimum(cell, self.n - 1)
        later = jax.tree_util.tree_map(lambda x: x[index], self.shared)
        # A cell whose own block is invalid where its pilot's is not (its
        # restitution factor: f e0 > 1 on an ensemble's base) keeps its own
        # carry, over before it starts (INVALID_INPUT).
        own = c.rocked | self.pilot | (c.status == Status.INVALID_INPUT)
        c = where_lanes(own, c, later)
        # Of the cell's own block (its pilot's has another size).
        c = jax.vmap(with_start_conditions, in_axes=(0,) + self.axes)(
            c, *self.inputs(per_lane)
        )
        return eqx.tree_at(lambda c: c.done, c, c.done | (cell >= self.n))

    def closed_form(self, c, block, lane_motion):
        """The lanes finished in closed form (`_free.py`): free rocking on a
        fixed base once the ground is still."""
        if not closed_form_tail(block, self.base):
            return jnp.zeros_like(c.done)
        return free_rocking_ready(c, block, lane_motion.end_time)  # elementwise

    def steps(self, state: _Lanes) -> _Lanes:
        """Step every lane until one or more finish: the lanes whose analysis is
        done, or with `pilot` whose shared phase ends (these keep their carry
        from before that attempt). No cell changes here, so the lanes' inputs
        are gathered once (in `refill`), not at every step."""
        block, lane_base, lane_motion = self.inputs(state.per_lane)
        opts, pilot, width = self.opts, self.pilot, state.cell.shape[0]

        def body(s: _Lanes) -> _Lanes:
            new, a = flat_step(
                s.carry,
                block,
                lane_base,
                lane_motion,
                self.duration,
                opts,
                self.axes,
                self.loop,
            )
            taken = new.steps - s.carry.steps
            ended = new.done | (new.segments >= opts.max_segments)
            ended = ended | self.closed_form(new, block, lane_motion)
            leaves = new.rocked | (a.t1 >= lane_motion.end_time)  # the shared phase
            finished = (s.cell < self.n) & (ended | (pilot & leaves))
            return eqx.tree_at(
                lambda s: (s.carry, s.finished, s.executed, s.useful),
                s,
                (
                    where_lanes(pilot & finished, s.carry, new),
                    finished,
                    s.executed + jnp.max(taken) * width,
                    s.useful + jnp.sum(taken),
                ),
            )

        state = eqx.tree_at(lambda s: s.finished, state, jnp.zeros_like(state.finished))
        with jax.named_scope(STEP_LOOP):  # a name to find it by in XLA's programs
            return jax.lax.while_loop(
                lambda s: ~jnp.any(s.finished) & jnp.any(s.cell < self.n), body, state
            )

    def refill(self, state: _Lanes, count) -> _Lanes:
        """The lanes that finished write their results (idle lanes nowhere)
        and take the queue's next cells (of the first `count`)."""
        finished, cell, c = state.finished, state.cell, state.carry
        index = jnp.where(finished, cell, self.n)  # other lanes write nowhere
        out = jax.tree_util.tree_map(
            lambda o, r: o.at[index].set(r, mode="drop"), state.out, c
        )
        cell = jnp.where(finished, state.queue + jnp.cumsum(finished) - 1, cell)
        cell = jnp.where(finished & (cell >= count), self.n, cell)
        fresh = self.gather(cell)
        return _Lanes(
            carry=where_lanes(finished, self.start(cell, fresh), c),
            cell=cell,
            queue=state.queue + jnp.sum(finished),
            out=out,
            executed=state.executed,
            useful=state.useful,
            per_lane=where_lanes(finished, fresh, state.per_lane),
            finished=finished,
        )

    def responses(self, carries: Carry):
        """The cells' responses and carries. On a fixed base, the lanes that
        `closed_form` ended (not done, within their segments, rocking; not
        pilots, whose responses are not used) finish in closed form."""
        blocks = Block(self.slenderness, self.size, **self.own)
        final = carries
        if closed_form_tail(blocks, self.base):
            ready = is_active(carries, self.opts)
            ready = ready & ~self.pilot & (carries.phase != Phase.TRANSLATION)
            motions = self.motion  # each cell's, for its window's end
            if self.layout is MotionLayout.SUITE:
                motions = self.motion.row(self.suite_index)
            window = lane_window(motions, self.duration, self.opts)
            final = free_rocking(carries, blocks, self.base, window, self.opts, ready)
        responses = jax.vmap(response, in_axes=(0, 0, 0, None))(
            final, blocks, self.base, self.opts
        )
        return responses, carries
