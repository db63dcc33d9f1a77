"""Isolator design by gradient descent: an objective over blocks x motions, Optax.

Derivatives are forward mode (`jax.jacfwd`): reverse mode cannot pass through
the `lax.while_loop` of the segment loop, and forward mode costs about one
extra primal per design parameter, which suits the two to four parameters of
an isolator. Event times move with the parameters and their derivatives are
carried (implicit differentiation of the event root find); impact maps and
regime changes are differentiated as they are applied.

Where the response is not differentiable (a block's outcome or impact count
changes under a small change of the parameters, or it overturns, where the
reported rotation is the constant pi / (2 alpha)) the derivative is that of the
branch the evaluation took: check `DesignResult.overturned` and the impact
counts before trusting a gradient there.
"""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._block import Block
from ._ground import AbstractGroundMotion, Record
from ._isolators import AbstractIsolator
from ._simulate import Outcome, Response, SolverOptions, run


def _lanes(blocks: Block, motions: AbstractGroundMotion):
    """Every (block, motion) pair as one lane: leaves of shape (n_blocks n_motions,)."""
    shape = np.broadcast_shapes(jnp.shape(blocks.slenderness), jnp.shape(blocks.size))
    nb = int(np.prod(shape))
    leaves = jax.tree_util.tree_leaves(motions)
    nm = (
        1
        if isinstance(motions, Record)
        else max([int(jnp.size(x)) for x in leaves] + [1])
    )

    def tile_blocks(x):
        return jnp.repeat(jnp.broadcast_to(jnp.asarray(x), (nb,)), nm)

    def tile_motions(x):
        return jnp.tile(jnp.broadcast_to(jnp.asarray(x), (nm,)), nb)

    lane_blocks = jax.tree_util.tree_map(tile_blocks, blocks)
    lane_motions = (
        motions
        if isinstance(motions, Record)
        else jax.tree_util.tree_map(tile_motions, motions)
    )
    return lane_blocks, lane_motions, (nb, nm)


def responses(
    base: AbstractIsolator,
    blocks: Block,
    motions: AbstractGroundMotion,
    *,
    duration=None,
    opts: SolverOptions = SolverOptions(),
) -> Response:
    """`run` for every (block, motion) pair, vmapped: fields of shape
    (n_blocks, n_motions).

    Traceable (use under `jax.jit` and `jax.jacfwd`); `blocks` and `motions` carry
    one batch axis (a `Record` is shared by all blocks).
    """
    lane_blocks, lane_motions, shape = _lanes(blocks, motions)
    if duration is None:
        duration = jnp.max(motions.end_time) + 5.0
    axes = (0, None if isinstance(motions, Record) else 0)
    out = jax.vmap(lambda b, m: run(b, base, m, duration, opts), in_axes=axes)(
        lane_blocks, lane_motions
    )
    return jax.tree_util.tree_map(lambda x: x.reshape(shape), out)


def isolator_objective(
    make_base: Callable[[dict], AbstractIsolator],
    blocks: Block,
    motions: AbstractGroundMotion,
    *,
    capacity: float = 0.3,
    penalty: float = 10.0,
    opts: SolverOptions = SolverOptions(),
) -> Callable[[dict], tuple]:
    """J = mean(max|theta|/alpha) + penalty mean(max(0, max|u| / capacity - 1)^2).

    Averages over every (block, motion) pair; `capacity` (m) is the isolator's
    displacement capacity, enforced by the quadratic penalty. Returns a function
    params -> (J, Response) for `jax.jacfwd(..., has_aux=True)`.
    """

    def objective(params):
        r = responses(make_base(params), blocks, motions, opts=opts)
        excess = jnp.maximum(r.max_base_displacement / capacity - 1.0, 0.0)
        value = jnp.mean(r.max_rotation) + penalty * jnp.mean(excess**2)
        return value, r

    return objective


class DesignResult(eqx.Module):
    """History of an isolator optimisation, one row per evaluated iterate.

    params: name -> array (steps + 1,); objective (steps + 1,); max_rotation,
    max_base_displacement, overturned: (steps + 1, n_blocks, n_motions); best:
    the parameters with the lowest objective.
    """

    params: dict
    objective: np.ndarray
    max_rotation: np.ndarray
    max_base_displacement: np.ndarray
    overturned: np.ndarray
    best: dict


@eqx.filter_jit
def _value_and_grad(make_base, x, lo, width, blocks, motions, capacity, penalty, opts):
    """Objective, its forward-mode gradient in x = (p - low) / width, responses.

    Module-level, so a second `tune_isolator` with the same `make_base` (and
    shapes) reuses the compile; `capacity` and `penalty` are traced.
    """
    objective = isolator_objective(
        make_base, blocks, motions, capacity=capacity, penalty=penalty, opts=opts
    )

    def with_aux(x):
        value, r = objective({k: lo[k] + width[k] * x[k] for k in x})
        return value, (value, r)

    grad, (value, r) = jax.jacfwd(with_aux, has_aux=True)(x)
    return value, grad, r


def tune_isolator(
    make_base: Callable[[dict], AbstractIsolator],
    init: dict,
    blocks: Block,
    motions: AbstractGroundMotion,
    *,
    bounds: dict,
    capacity: float = 0.3,
    penalty: float = 10.0,
    steps: int = 30,
    learning_rate: float = 0.05,
    optimizer: optax.GradientTransformation | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-10,
) -> DesignResult:
    """Minimise `isolator_objective` over the parameters in `init` with Optax.

    `make_base(params)` builds the isolator from a dict of scalars (e.g.
    `lambda p: LinearIsolator(p["period"], p["damping"], 0.5)`); `bounds` maps
    each name to (low, high), enforced by projection after every update. The
    default optimiser is Adam on parameters scaled by their bounds' width, so one
    learning rate suits seconds and damping ratios alike. Gradients are forward
    mode through the whole simulation (one compile per `make_base` function and
    shapes: calling again with the same `make_base` reuses it).
    """
    names = sorted(init)
    if set(bounds) != set(names):
        raise ValueError(f"`bounds` must give (low, high) for each of {names}")
    for k in names:
        lo, hi = bounds[k]
        if not lo < hi:
            raise ValueError(f"bounds[{k!r}] must have low < high, got {bounds[k]}")
        if not lo <= init[k] <= hi:
            raise ValueError(f"init[{k!r}] = {init[k]} is outside bounds {bounds[k]}")
    lo = {k: float(bounds[k][0]) for k in names}
    width = {k: float(bounds[k][1]) - float(bounds[k][0]) for k in names}
    opts = SolverOptions(rtol=rtol, atol=atol)
    problem = (
        {k: jnp.asarray(v) for k, v in lo.items()},
        {k: jnp.asarray(v) for k, v in width.items()},
        blocks,
        motions,
        jnp.asarray(capacity, dtype=float),
        jnp.asarray(penalty, dtype=float),
        opts,
    )

    def value_and_grad(x):
        return _value_and_grad(make_base, x, *problem)

    optimizer = optimizer or optax.adam(learning_rate)
    x = {k: jnp.asarray((init[k] - lo[k]) / width[k]) for k in names}
    state = optimizer.init(x)
    rows = []
    for i in range(steps + 1):
        value, grad, r = value_and_grad(x)
        rows.append(
            (
                {k: lo[k] + width[k] * float(x[k]) for k in names},
                float(value),
                np.asarray(r.max_rotation),
                np.asarray(r.max_base_displacement),
                np.asarray(r.outcome) == Outcome.OVERTURNED,
            )
        )
        if i == steps:
            break
        updates, state = optimizer.update(grad, state, x)
        x = jax.tree_util.tree_map(
            lambda v: jnp.clip(v, 0.0, 1.0), optax.apply_updates(x, updates)
        )
    values = np.array([row[1] for row in rows])
    best = rows[int(np.argmin(values))][0]
    return DesignResult(
        params={k: np.array([row[0][k] for row in rows]) for k in names},
        objective=values,
        max_rotation=np.stack([row[2] for row in rows]),
        max_base_displacement=np.stack([row[3] for row in rows]),
        overturned=np.stack([row[4] for row in rows]),
        best=best,
    )
