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

import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._block import Block
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator
from ._misc import is_count
from ._record import Record
from ._results import ATOL, RTOL, Outcome, Response, SolverOptions
from ._simulate import run


def _pairs(blocks: Block, motions: AbstractGroundMotion):
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
    lane_blocks, lane_motions, shape = _pairs(blocks, motions)
    if duration is None:
        duration = jnp.max(motions.end_time) + 5.0
    axes = (0, None if isinstance(motions, Record) else 0)
    out = jax.vmap(lambda b, m: run(b, base, m, duration, opts), in_axes=axes)(
        lane_blocks, lane_motions
    )
    return jax.tree_util.tree_map(lambda x: x.reshape(shape), out)


def _objective(base, blocks, motions, capacity, penalty, opts):
    r = responses(base, blocks, motions, opts=opts)
    excess = jnp.maximum(r.max_base_displacement / capacity - 1.0, 0.0)
    return jnp.mean(r.max_rotation) + penalty * jnp.mean(excess**2), r


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
        return _objective(make_base(params), blocks, motions, capacity, penalty, opts)

    return objective


def _real(name: str, value) -> float:
    """`value` as a finite float (`ValueError` naming `name` otherwise)."""
    kind = np.asarray(value).dtype.kind if value is not None else None
    if kind not in ("f", "i", "u") or np.ndim(value) != 0:
        raise ValueError(f"`{name}` must be a real number, got {value!r}")
    if not math.isfinite(float(value)):
        raise ValueError(f"`{name}` must be finite, got {value!r}")
    return float(value)


def _check_design(init, bounds, capacity, penalty, steps, learning_rate) -> list:
    """`tune_isolator`'s arguments, checked before anything compiles; returns
    the design variables' names."""
    if not isinstance(init, dict) or not init:
        raise ValueError(
            "`init` must be a non-empty dict of design parameters (name -> value), "
            f"got {init!r}"
        )
    names = sorted(init)
    if not isinstance(bounds, dict) or set(bounds) != set(names):
        raise ValueError(f"`bounds` must give (low, high) for each of {names}")
    for k in names:
        if np.shape(bounds[k]) != (2,):
            raise ValueError(f"bounds[{k!r}] must be (low, high), got {bounds[k]!r}")
        lo, hi = (_real(f"bounds[{k!r}]", v) for v in bounds[k])
        if not lo < hi:
            raise ValueError(f"bounds[{k!r}] must have low < high, got {bounds[k]}")
        if not lo <= _real(f"init[{k!r}]", init[k]) <= hi:
            raise ValueError(f"init[{k!r}] = {init[k]} is outside bounds {bounds[k]}")
    if not _real("capacity", capacity) > 0:
        raise ValueError(f"`capacity` must be finite and > 0 (m), got {capacity}")
    if not _real("penalty", penalty) >= 0:
        raise ValueError(f"`penalty` must be finite and >= 0, got {penalty}")
    if not _real("learning_rate", learning_rate) > 0:
        raise ValueError(f"`learning_rate` must be finite and > 0, got {learning_rate}")
    if not is_count(steps) or steps < 0:
        raise ValueError(f"`steps` must be an integer >= 0, got {steps!r}")
    return names


class DesignResult(eqx.Module):
    """History of an isolator optimisation, one row per evaluated iterate.

    params: name -> array (steps + 1,); objective (steps + 1,); gradient: name ->
    dJ/dp (steps + 1,) in the parameter's units; max_rotation,
    max_base_displacement, overturned: (steps + 1, n_blocks, n_motions); best:
    the parameters with the lowest objective.
    """

    params: dict
    objective: np.ndarray
    gradient: dict
    max_rotation: np.ndarray
    max_base_displacement: np.ndarray
    overturned: np.ndarray
    best: dict


@eqx.filter_jit
def _value_and_grad(base, tangents, blocks, motions, capacity, penalty, opts):
    """Objective at `base`, its derivatives along each of `tangents` (the base's
    derivative in each design variable, stacked on a leading axis; forward
    mode), and the responses.

    Free of `make_base` (the chain rule through it is taken outside), so every
    tuning of one isolator type with as many design variables (and the same
    shapes) shares the compile, whatever function builds the isolator.
    """

    def objective(base):
        return _objective(base, blocks, motions, capacity, penalty, opts)

    def push(tangent):
        return jax.jvp(objective, (base,), (tangent,), has_aux=True)

    return jax.vmap(push, out_axes=(None, 0, None))(tangents)


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
    rtol: float = RTOL,
    atol: float = ATOL,
) -> DesignResult:
    """Minimise `isolator_objective` over the parameters in `init` with Optax.

    `make_base(params)` builds the isolator from a dict of scalars (e.g.
    `lambda p: LinearIsolator(p["period"], p["damping"], 0.5)`); `bounds` maps
    each name to (low, high), enforced by projection after every update. The
    default optimiser is Adam on parameters scaled by their bounds' width, so one
    learning rate suits seconds and damping ratios alike. Gradients are forward
    mode through the whole simulation; one compile per isolator type, number of
    design variables and shapes, shared by every `make_base` (a new lambda
    does not recompile).
    """
    names = _check_design(init, bounds, capacity, penalty, steps, learning_rate)
    lo = {k: float(bounds[k][0]) for k in names}
    width = {k: float(bounds[k][1]) - float(bounds[k][0]) for k in names}
    opts = SolverOptions(rtol=rtol, atol=atol)
    problem = (
        blocks,
        motions,
        jnp.asarray(capacity, dtype=float),
        jnp.asarray(penalty, dtype=float),
        opts,
    )

    def base_at(x):
        return make_base({k: lo[k] + width[k] * x[k] for k in names})

    base = base_at({k: (init[k] - lo[k]) / width[k] for k in names})
    if not isinstance(base, AbstractIsolator) or base.n_states == 0:
        raise ValueError(
            "`make_base` must return an isolated base (LinearIsolator or "
            f"FrictionPendulum) built from the parameters, got {type(base).__name__}"
        )

    units = [{j: jnp.asarray(float(j == k)) for j in names} for k in names]

    def value_and_grad(x):
        # d base / d x_k by forward mode through `make_base` (eager and cheap),
        # then the chain rule inside the compiled simulation.
        tangents = [jax.jvp(base_at, (x,), (u,))[1] for u in units]
        tangents = jax.tree_util.tree_map(lambda *t: jnp.stack(t), *tangents)
        value, grad, r = _value_and_grad(base_at(x), tangents, *problem)
        return value, {k: grad[i] for i, k in enumerate(names)}, r

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
                {k: float(grad[k]) / width[k] for k in names},
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
        gradient={k: np.array([row[2][k] for row in rows]) for k in names},
        max_rotation=np.stack([row[3] for row in rows]),
        max_base_displacement=np.stack([row[4] for row in rows]),
        overturned=np.stack([row[5] for row in rows]),
        best=best,
    )
