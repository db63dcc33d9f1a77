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
import warnings
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._block import Block
from ._dynamics import check_restitution
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator
from ._misc import broadcast_batch_shape, is_count
from ._record import Record
from ._results import (
    ATOL,
    MAX_SEGMENTS,
    REST_TOLERANCE,
    RTOL,
    Outcome,
    Response,
    SolverOptions,
    Status,
    analysis_window,
)
from ._scene import fixed_base, prepare
from ._simulate import run


def _pairs(blocks: Block, motions: AbstractGroundMotion):
    """Every (block, motion) pair as one lane: leaves of shape (n_blocks
    n_motions,), and the motions' `jax.vmap` in_axes. One record is shared by
    every lane; a suite's lanes read its records in place (`RecordSignal.row`)."""
    if not isinstance(blocks, Block):
        raise ValueError(f"`blocks` must be a Block, got {type(blocks).__name__}")
    if not isinstance(motions, AbstractGroundMotion):
        raise ValueError(
            "`motions` must be a ground motion (a pulse, a Record or a suite), "
            f"got {type(motions).__name__}"
        )
    shape = broadcast_batch_shape(blocks)  # (every parameter of the blocks)
    if len(shape) > 1:
        raise ValueError(
            f"`blocks` must have one batch axis (n_blocks) or none, got shape {shape}"
        )
    batch = motions.batch_shape
    if len(batch) > 1:
        raise ValueError(
            "`motions` must have one batch axis (a suite or a batch of pulses) "
            f"or none, got shape {batch}"
        )
    nb, nm = int(np.prod(shape)), int(np.prod(batch))
    of_suite = isinstance(motions, Record) and bool(batch)

    def tile_blocks(x):
        return jnp.repeat(jnp.broadcast_to(jnp.asarray(x), (nb,)), nm)

    def tile_motions(x):
        return jnp.tile(jnp.broadcast_to(jnp.asarray(x), (nm,)), nb)

    lane_blocks = jax.tree_util.tree_map(tile_blocks, blocks)
    if of_suite:  # (its table of peaks: computed once, unbatched)
        suite = prepare(motions)
        return (
            lane_blocks,
            suite.row(tile_motions(jnp.arange(nm))),
            suite.row_axes(),
            (nb, nm),
        )
    if isinstance(motions, Record):
        return lane_blocks, motions, None, (nb, nm)
    return lane_blocks, jax.tree_util.tree_map(tile_motions, motions), 0, (nb, nm)


def responses(
    base: AbstractIsolator,
    blocks: Block,
    motions: AbstractGroundMotion,
    *,
    duration=None,
    opts: SolverOptions | None = None,
) -> Response:
    """The analysis of every (block, motion) pair on one base, vmapped.

    Each pair is the analysis of `simulate` (without histories), all pairs
    under one `jax.vmap`. Traceable: use it under `jax.jit` and `jax.jacfwd`
    (`isolator_objective` does). The parameters are not checked here: a module
    built from traced values with a parameter out of its range gives
    `Status.INVALID_INPUT` and NaN results.

    Args:
        base: the base, without batch axes.
        blocks: the blocks, with one batch axis (n_blocks) or none.
        motions: the ground motions, with one batch axis (n_motions) or none;
            one `Record`, shared by all blocks; or a suite of records
            (`Record.stack`, its motion axes flattened: n_motions records),
            whose samples every lane reads in place.
        duration: the length of every analysis (s); default None: each runs
            until its block's fate is decided, for at most 60 s after the
            end of its own motion (`simulate`).
        opts: the numerical options (`SolverOptions`); default None: those
            `simulate` takes by default for `motions` (its step limit raised
            for a long record).

    Returns:
        A `Response` whose fields have shape (n_blocks, n_motions).

    Examples:
        >>> import jax.numpy as jnp, jaxrock as jr
        >>> from jaxrock.design import responses
        >>> blocks = jr.Block(jnp.array([4.0, 6.0]), 1.0)
        >>> pulses = jr.MPPulse(jnp.array([0.6, 0.8]), 2.0, 2.0, 0.0)
        >>> r = responses(jr.LinearIsolator(1.5, 0.2, 0.5), blocks, pulses)
        >>> r.max_rotation.shape, r.max_rotation.round(3).tolist()
        ((2, 2), [[0.0, 0.0], [0.001, 0.068]])
    """
    opts = _default_options(motions) if opts is None else opts
    lane_blocks, lane_motions, motion_axes, shape = _pairs(blocks, motions)
    if duration is None:  # run until decided
        duration, _ = analysis_window(motions, None)
        opts = eqx.tree_at(lambda o: o.until_decided, opts, jnp.asarray(True))
    out = jax.vmap(
        lambda b, m: run(b, base, m, duration, opts), in_axes=(0, motion_axes)
    )(lane_blocks, lane_motions)
    return jax.tree_util.tree_map(lambda x: x.reshape(shape), out)


def _default_options(motions, rtol=RTOL, atol=ATOL) -> SolverOptions:
    """`simulate`'s default options for `motions`: its step limit raised for
    a long record (`SolverOptions.for_motion`)."""
    return SolverOptions.for_motion(
        motions,
        rtol=rtol,
        atol=atol,
        max_steps=None,
        max_segments=MAX_SEGMENTS,
        rest_tolerance=REST_TOLERANCE,
        solver=None,
    )


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
    opts: SolverOptions | None = None,
) -> Callable[[dict], tuple]:
    """The design objective of an isolator over blocks x motions.

    J = mean(max|theta| / alpha) + penalty mean(max(0, max|u| / capacity - 1)^2),
    both means over every (block, motion) pair (`responses`): the mean peak
    rotation, normalised by each block's alpha (an overturned block counts
    pi / (2 alpha)), plus a quadratic penalty on the peak base displacements
    max|u| (m) beyond the isolator's displacement capacity (m). J is
    dimensionless. Derivatives are forward mode (`jax.jacfwd`); where an
    outcome or an impact count changes under a small change of the
    parameters, or a block overturns, J is not differentiable and the
    derivative is that of the branch the evaluation took.

    Args:
        make_base: builds the isolator from a dict of parameters (name ->
            scalar, in the parameter's units, e.g. a period in s).
        blocks: the blocks, with one batch axis or none.
        motions: the ground motions, with one batch axis or none; one
            `Record`, shared by all blocks; or a suite of records
            (`Record.stack`).
        capacity: the isolator's displacement capacity (m); default 0.3.
        penalty: the weight of the penalty (-); default 10.
        opts: the numerical options (`SolverOptions`); default None:
            `simulate`'s for `motions` (`responses`).

    Returns:
        A function params -> (J, Response), for
        `jax.jacfwd(..., has_aux=True)`; the `Response` has fields of shape
        (n_blocks, n_motions).

    Examples:
        >>> import jax, jax.numpy as jnp, jaxrock as jr
        >>> from jaxrock.design import isolator_objective
        >>> blocks = jr.Block(jnp.array([4.0, 6.0]), 1.0)
        >>> pulses = jr.MPPulse(jnp.array([0.6, 0.8]), 2.0, 2.0, 0.0)
        >>> J = isolator_objective(
        ...     lambda p: jr.LinearIsolator(p["period"], p["damping"], 0.5),
        ...     blocks, pulses)
        >>> grad, r = jax.jacfwd(J, has_aux=True)({"period": 1.5, "damping": 0.2})
        >>> {k: round(float(v), 3) for k, v in grad.items()}  # period: per s
        {'damping': 0.323, 'period': -0.173}
    """

    _check_objective(capacity, penalty)
    opts = _default_options(motions) if opts is None else opts

    def objective(params):
        return _objective(make_base(params), blocks, motions, capacity, penalty, opts)

    return objective


def _check_objective(capacity, penalty) -> None:
    """The objective's arguments (`ValueError` naming them)."""
    if not _real("capacity", capacity) > 0:
        raise ValueError(f"`capacity` must be finite and > 0 (m), got {capacity}")
    if not _real("penalty", penalty) >= 0:
        raise ValueError(f"`penalty` must be finite and >= 0, got {penalty}")


def _real(name: str, value) -> float:
    """`value` as a finite float (`ValueError` naming `name` otherwise)."""
    kind = np.asarray(value).dtype.kind if value is not None else None
    if kind not in ("f", "i", "u") or np.ndim(value) != 0:
        raise ValueError(f"`{name}` must be a real number, got {value!r}")
    if not math.isfinite(float(value)):
        raise ValueError(f"`{name}` must be finite, got {value!r}")
    return float(value)


def _check_design(init, bounds, steps, learning_rate) -> list:
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
    if not _real("learning_rate", learning_rate) > 0:
        raise ValueError(f"`learning_rate` must be finite and > 0, got {learning_rate}")
    if not is_count(steps) or steps < 0:
        raise ValueError(f"`steps` must be an integer >= 0, got {steps!r}")
    return names


class DesignResult(eqx.Module):
    """The iterates of an isolator optimisation (`tune_isolator`), one row each.

    Row i holds the parameters after i updates and what they give: `steps`
    updates give steps + 1 rows. J is the dimensionless objective of
    `isolator_objective`. Check `overturned` (and the impact counts) before
    trusting a gradient: where a block overturns, its rotation is the
    constant pi / (2 alpha).

    Attributes:
        params: name -> the parameter's values (in its units), shape
            (steps + 1,).
        objective: J (-), shape (steps + 1,).
        gradient: name -> dJ/dp (per unit of the parameter, e.g. 1/s for a
            period), shape (steps + 1,).
        max_rotation: max |theta| / alpha (-), shape
            (steps + 1, n_blocks, n_motions).
        max_base_displacement: max |u| (m), same shape.
        overturned: whether each block overturned (bool), same shape.
        status: each analysis's `Status` code, same shape: anything but
            SUCCESS (or CAPACITY_EXCEEDED, an isolator past its geometric
            limit) means that its numbers, and so J, are not final.
        best: the parameters with the lowest objective, name -> float, among
            the iterates whose analyses are all final (`tune_isolator` warns
            when one is not).

    `tune_isolator` returns one (see its example).
    """

    params: dict
    objective: np.ndarray
    gradient: dict
    max_rotation: np.ndarray
    max_base_displacement: np.ndarray
    overturned: np.ndarray
    status: np.ndarray
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

    Gradient descent on the dimensionless objective J of `isolator_objective`,
    with gradients in forward mode through the whole simulation. The
    parameters are scaled to [0, 1] by their bounds and projected onto them
    after every update; the default optimiser is Adam on the scaled
    parameters, so one learning rate suits periods (s) and damping ratios (-)
    alike. One compile per isolator type, number of design variables and
    shapes, shared by every `make_base` (a new lambda does not recompile).

    Args:
        make_base: builds the isolator from a dict of scalars, e.g.
            `lambda p: LinearIsolator(p["period"], p["damping"], 0.5)`; it
            must return an isolated base.
        init: the starting parameters, name -> value (in the parameter's
            units, e.g. s for a period), each within its bounds.
        blocks: the blocks, with one batch axis or none.
        motions: the ground motions, with one batch axis or none; one
            `Record`, shared by all blocks; or a suite of records
            (`Record.stack`).
        bounds: name -> (low, high) for every name of `init`, low < high, in
            the parameter's units.
        capacity: the isolator's displacement capacity (m), > 0; default 0.3.
        penalty: the weight of the penalty (-), >= 0; default 10.
        steps: the number of updates, an integer >= 0 (steps + 1
            evaluations); default 30.
        learning_rate: Adam's learning rate on the scaled parameters (-),
            > 0; default 0.05.
        optimizer: an Optax optimiser of the scaled parameters; default
            `optax.adam(learning_rate)`.
        rtol: the integrator's relative tolerance (-); default 1e-8.
        atol: the integrator's absolute tolerance (in the state's units: rad,
            rad/s, m, m/s); default 1e-10.

    Returns:
        A `DesignResult` with every evaluated iterate and the best parameters.
        An analysis that does not reach its end (a `status` other than
        SUCCESS or CAPACITY_EXCEEDED) makes J not final at its iterate: a
        `UserWarning` says where, and `best` skips those iterates.

    Raises:
        ValueError: an `init` or `bounds` that is not a dict of finite real
            numbers for the same names, a bound with low >= high, a starting
            value outside its bounds, a `capacity`, `penalty`,
            `learning_rate` or `steps` out of its range, a `make_base`
            that does not return an isolated base, or a block whose
            `restitution_factor` f gives f e0 > 1 on it (as `simulate`).

    Examples:
        >>> import jax.numpy as jnp, jaxrock as jr
        >>> from jaxrock.design import tune_isolator
        >>> result = tune_isolator(
        ...     lambda p: jr.LinearIsolator(p["period"], p["damping"], 0.5),
        ...     {"period": 1.5, "damping": 0.2},
        ...     jr.Block(jnp.array([4.0, 6.0]), 1.0),
        ...     jr.MPPulse(jnp.array([0.6, 0.8]), 2.0, 2.0, 0.0),
        ...     bounds={"period": (1.0, 3.0), "damping": (0.05, 0.5)},
        ...     steps=3,
        ... )
        >>> result.objective.round(4)
        array([0.0172, 0.0023, 0.0001, 0.    ])
        >>> {k: round(v, 3) for k, v in result.best.items()}
        {'damping': 0.145, 'period': 1.743}
    """
    _check_objective(capacity, penalty)
    names = _check_design(init, bounds, steps, learning_rate)
    scale = _Scaling(names, bounds)
    problem = (
        blocks,
        motions,
        jnp.asarray(capacity, dtype=float),
        jnp.asarray(penalty, dtype=float),
        _default_options(motions, rtol, atol),
    )

    x = scale.unit(init)
    value_and_grad = _value_and_grad_of(make_base, scale, problem, x)
    optimizer = optimizer or optax.adam(learning_rate)
    rows = _descend(value_and_grad, optimizer, x, steps, scale)
    return _design_result(rows, names)


def _value_and_grad_of(make_base, scale: "_Scaling", problem: tuple, x: dict):
    """J, dJ/dx and the responses as a function of the scaled point x, for the
    isolator `make_base` builds (checked at x: an isolated base)."""

    def base_at(x):
        return make_base(scale.params(x))

    base = base_at(x)
    if not isinstance(base, AbstractIsolator) or fixed_base(base):
        raise ValueError(
            "`make_base` must return an isolated base (LinearIsolator, "
            "FrictionPendulum, BilinearIsolator, ...) built from the parameters, "
            f"got {type(base).__name__}"
        )
    check_restitution(problem[0], base)  # f e0 <= 1 (as `simulate` checks)
    names = scale.names
    for k in names:  # the ends of each bound, the others at x
        for end in (0.0, 1.0):
            try:
                base_at(x | {k: jnp.asarray(end)})
            except ValueError as e:
                which = "low" if end == 0.0 else "high"
                raise ValueError(
                    f"bounds[{k!r}]: `make_base` fails at its {which} end: {e}"
                ) from None
    units = [{j: jnp.asarray(float(j == k)) for j in names} for k in names]

    def value_and_grad(x):
        # d base / d x_k by forward mode through `make_base` (eager and cheap),
        # then the chain rule inside the compiled simulation.
        tangents = [jax.jvp(base_at, (x,), (u,))[1] for u in units]
        tangents = jax.tree_util.tree_map(lambda *t: jnp.stack(t), *tangents)
        value, grad, r = _value_and_grad(base_at(x), tangents, *problem)
        return value, {k: grad[i] for i, k in enumerate(names)}, r

    return value_and_grad


class _Scaling:
    """The design variables scaled to [0, 1] by their bounds."""

    def __init__(self, names, bounds):
        self.names = names
        self.lo = {k: float(bounds[k][0]) for k in names}
        self.width = {k: float(bounds[k][1]) - float(bounds[k][0]) for k in names}

    def params(self, x) -> dict:
        """The parameters (their units) at the scaled point x."""
        return {k: self.lo[k] + self.width[k] * x[k] for k in self.names}

    def unit(self, params) -> dict:
        """The scaled point of the parameters."""
        return {
            k: jnp.asarray((params[k] - self.lo[k]) / self.width[k]) for k in self.names
        }


def _descend(value_and_grad, optimizer, x, steps: int, scale: _Scaling) -> list:
    """`steps` projected updates of the scaled point x from `optimizer`;
    returns a row per evaluation: the parameters, J, dJ/d parameter, and the
    responses' max rotation, max base displacement and overturning."""
    state = optimizer.init(x)
    rows = []
    for i in range(steps + 1):
        value, grad, r = value_and_grad(x)
        rows.append(
            (
                {k: float(v) for k, v in scale.params(x).items()},
                float(value),
                {k: float(grad[k]) / scale.width[k] for k in scale.names},
                np.asarray(r.max_rotation),
                np.asarray(r.max_base_displacement),
                np.asarray(r.outcome) == Outcome.OVERTURNED,
                np.asarray(r.status),
            )
        )
        if i == steps:
            break
        updates, state = optimizer.update(grad, state, x)
        x = jax.tree_util.tree_map(
            lambda v: jnp.clip(v, 0.0, 1.0), optax.apply_updates(x, updates)
        )
    return rows


def _design_result(rows: list, names) -> DesignResult:
    """The `DesignResult` of `_descend`'s rows; `best`: the lowest J among the
    iterates whose analyses are all final (among all, with a warning, when
    none is)."""
    values = np.array([row[1] for row in rows])
    status = np.stack([row[6] for row in rows])
    final = (status == Status.SUCCESS) | (status == Status.CAPACITY_EXCEEDED)
    settled = final.reshape(len(rows), -1).all(axis=1)
    if not settled.all():
        codes = sorted({Status(int(c)).name for c in np.unique(status[~final])})
        warnings.warn(
            f"{int((~final).sum())} of {final.size} analyses did not reach their "
            f"end ({', '.join(codes)}), at iterates "
            f"{np.flatnonzero(~settled).tolist()}: J there is not final; `best` "
            + ("is chosen among the other iterates" if settled.any() else "is not")
            + " (see `DesignResult.status`)",
            stacklevel=3,
        )
    # (A NaN J, of an invalid analysis, is never the best.)
    ranked = np.where(np.isnan(values) | (settled.any() & ~settled), np.inf, values)
    return DesignResult(
        params={k: np.array([row[0][k] for row in rows]) for k in names},
        objective=values,
        gradient={k: np.array([row[2][k] for row in rows]) for k in names},
        max_rotation=np.stack([row[3] for row in rows]),
        max_base_displacement=np.stack([row[4] for row in rows]),
        overturned=np.stack([row[5] for row in rows]),
        status=status,
        best=rows[int(np.argmin(ranked))][0],
    )
