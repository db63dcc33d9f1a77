"""One analysis: the segment loop of a hybrid (event-driven) rocking simulation.

Each segment is one Diffrax solve of the vector field in one phase (translation,
rising, falling) until an event (uplift, apex, impact, rising again, overturn,
a new peak of |u|) or the end of the window; the loop then applies the
transition (the impact map at an impact) and starts the next segment. The loop
is a `lax.while_loop`, so `simulate` runs under `jit` and `vmap`: a finished
lane performs zero-length solves until every lane is done.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._block import Block
from ._dynamics import Phase, vector_field
from ._events import EVENT_ATOL, EVENT_RTOL, BracketedNewton
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator
from ._misc import one_real_number, positive
from ._model import (
    Carry,
    check_base_and_motion,
    initial_carry,
    is_active,
    response,
    segment_setup,
    transition,
)
from ._results import (
    ATOL,
    MAX_SEGMENTS,
    REST_TOLERANCE,
    RTOL,
    EventKind,
    History,
    Response,
    SolverOptions,
)


def _solve_segment(c: Carry, block, base, motion, duration, opts, dense=False):
    """Integrate from c.t to the next event (or `duration`): a Diffrax solution."""
    active, args, conditions, t_stop, _, controller = segment_setup(
        c, block, base, motion, duration, opts
    )
    if opts.step is None:
        # The first step is the previous segment's mean step (no step-size
        # selection, which costs two evaluations a segment).
        root_finder, dt0 = BracketedNewton(rtol=EVENT_RTOL, atol=EVENT_ATOL), c.dt
    else:
        controller, root_finder, dt0 = diffrax.ConstantStepSize(), None, opts.step
    # Diffrax takes the conditions present, in order (its mask: a tuple).
    event = diffrax.Event(
        tuple(jax.tree_util.tree_leaves(conditions)),
        root_finder=root_finder,
        direction=False,
    )
    return diffrax.diffeqsolve(
        diffrax.ODETerm(vector_field),
        opts.solver,
        t0=c.t,
        # A finished lane makes a zero-length solve (vmap runs every lane's body).
        t1=jnp.where(active, t_stop, c.t),
        dt0=dt0,
        y0=c.y,
        args=args,
        event=event,
        stepsize_controller=controller,
        saveat=diffrax.SaveAt(t1=True, dense=dense),
        max_steps=opts.max_steps,
        throw=False,
        adjoint=diffrax.ForwardMode(),
    )


def run(block, base, motion, duration, opts: SolverOptions) -> Response:
    """The whole analysis as one traceable function (for `jit`, `vmap`, `jacfwd`)."""

    def cond(c):
        return is_active(c, opts)

    def body(c):
        sol = _solve_segment(c, block, base, motion, duration, opts)
        return transition(c, sol, block, base, motion, duration, opts)

    valid = opts.valid() & jnp.isfinite(duration) & (duration > 0)
    motion = motion.with_peaks()
    carry = jax.lax.while_loop(cond, body, initial_carry(block, base, motion, valid))
    return response(carry, block, opts)


_run_jit = eqx.filter_jit(run)


@eqx.filter_jit
def _segment_dense(c, block, base, motion, duration, opts):
    """One segment with its dense output, and the carry after its transition."""
    sol = _solve_segment(c, block, base, motion, duration, opts, dense=True)
    return transition(c, sol, block, base, motion, duration, opts), sol


# Times evaluated per call on a segment's dense output (one compile for all).
_WINDOW = 256


@eqx.filter_jit
def _evaluate(sol, ts):
    return jax.vmap(sol.evaluate)(ts)


def _dense_states(sol, ts: np.ndarray):
    """The states at times `ts` on a segment's dense output, `_WINDOW` at a time."""
    parts = []
    for i in range(0, ts.size, _WINDOW):
        window = ts[i : i + _WINDOW]
        padded = np.pad(window, (0, _WINDOW - window.size), mode="edge")
        ys = _evaluate(sol, padded)
        parts.append(jax.tree_util.tree_map(lambda x: np.asarray(x)[: window.size], ys))
    return jax.tree_util.tree_map(lambda *x: np.concatenate(x), *parts)


def _rows(t, y, regime) -> np.ndarray:
    """History rows (t, theta, theta', u, u', z, regime, base state...) from
    states at times t; z is left 0 (`_history` computes it from the base
    states of all rows at once)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    states = np.zeros((t.size, 0)) if y[2] is None else np.asarray(y[2])
    out = np.zeros((t.size, 7 + states.size // t.size))
    out[:, 0] = t
    out[:, 1] = np.asarray(y[0]).reshape(t.size)
    out[:, 2] = np.asarray(y[1]).reshape(t.size)
    out[:, 7:] = states.reshape(t.size, -1)
    out[:, 3:5] = out[:, 7:9] if states.size else 0.0
    out[:, 6] = regime
    return out


@eqx.filter_jit
def _acceleration(motion, t):
    return jax.vmap(motion.acceleration)(t)


@eqx.filter_jit
def _hysteretic(base, states):
    return jax.vmap(base.hysteretic)(states)


def _rowwise(f, module, x: np.ndarray) -> np.ndarray:
    """f(module, x) for a history's rows x, compiled (op by op it took
    seconds); the rows padded to a power of two so that histories of other
    lengths reuse a handful of compiles."""
    n = x.shape[0]
    pad = [(0, (1 << (n - 1).bit_length()) - n)] + [(0, 0)] * (x.ndim - 1)
    return np.asarray(f(module, np.pad(x, pad, mode="edge")))[:n]


def _history(block, base, motion, duration, opts, step):
    """The same segments in a Python loop, sampled every `step` (s) and at
    every event.

    Returns the final carry and a `History`; at an event both the state just
    before and just after the transition are recorded (same time).
    """
    duration = float(duration)
    grid = np.linspace(0.0, duration, int(np.ceil(duration / step - 1e-9)) + 1)
    c = initial_carry(block, base, motion)

    def regime(carry):
        return 0.0 if int(carry.phase) == Phase.TRANSLATION else float(carry.sign)

    rows = [_rows(c.t, c.y, regime(c))]
    times, kinds = ([0.0], ["uplift"]) if bool(c.rocked) else ([], [])
    while not bool(c.done) and int(c.segments) < opts.max_segments:
        new, sol = _segment_dense(c, block, base, motion, duration, opts)
        t0, t1 = float(c.t), float(new.t)
        # The grid inside the segment, then the state just before the event.
        ts = np.append(grid[(grid > t0) & (grid < t1)], t1)
        ys = _dense_states(sol, ts)
        rows += [_rows(ts, ys, regime(c)), _rows(new.t, new.y, regime(new))]
        kind = EventKind(int(new.kind))
        if kind != EventKind.END:
            times.append(t1)
            kinds.append(kind.name.lower())
        c = new
    h = np.concatenate(rows)
    if base.hysteretic_state:
        h[:, 5] = _rowwise(_hysteretic, base, h[:, 7:])  # z
    history = History(
        t=h[:, 0],
        theta=h[:, 1],
        theta_dot=h[:, 2],
        u=h[:, 3],
        u_dot=h[:, 4],
        z=h[:, 5],
        regime=h[:, 6],
        ground_acceleration=_rowwise(_acceleration, motion, h[:, 0]),
        event_times=np.asarray(times),
        event_kinds=tuple(kinds),
        alpha=float(block.alpha),
    )
    return c, history


def simulate(
    block: Block,
    base: AbstractIsolator,
    motion: AbstractGroundMotion,
    *,
    duration: float | None = None,
    rtol: float = RTOL,
    atol: float = ATOL,
    history: bool = False,
    history_step: float | None = None,
    max_steps: int | None = None,
    max_segments: int = MAX_SEGMENTS,
    rest_tolerance: float = REST_TOLERANCE,
    solver: diffrax.AbstractSolver | None = None,
) -> Response:
    """Simulate one block on a base under a ground motion (SI units, float64).

    The block rocks about its corners (rotation theta, rad) on a base that
    moves relative to the ground (displacement u, m) under the ground
    acceleration x_g''(t) (m/s^2), from rest at t = 0: a hybrid analysis, one
    Diffrax solve per segment between events (uplift, apex, impact, overturn,
    ...), with the impact map applied at each impact. Works under `jax.jit`,
    `jax.vmap` and `jax.jacfwd` (with `history=False`); physical parameters
    and `duration` are traced, so new values do not recompile. Modules built
    from traced values are not checked at construction: a parameter out of
    its range then gives `Status.INVALID_INPUT` and NaN results.

    Args:
        block: the rigid block.
        base: `FixedBase()`, `LinearIsolator(...)`, `FrictionPendulum(...)` or
            `IntegratedFrictionPendulum(...)`.
        motion: an `MPPulse`, a `SinePulse` or a `Record`.
        duration: length of the analysis (s), one number > 0; default: the
            end of the excitation plus 5 s.
        rtol: the integrator's relative tolerance (-). Events are located to
            about 1e-12 s on the dense output whatever the tolerances.
        atol: the integrator's absolute tolerance, in the state's units (rad,
            rad/s, m, m/s).
        history: also return the time histories (`Response.history`), computed
            by a Python loop of compiled segments.
        history_step: spacing of the history's samples (s), one number > 0;
            every event is recorded as well. Default: duration / 2000, at
            most 0.01 s.
        max_steps: the solver's step limit in one segment; default 16384,
            raised for long records to 4 steps a sample (a guard against
            runaway solves that a valid record never reaches).
        max_segments: the limit on segments (events) of the analysis; default
            2000.
        rest_tolerance: the rest rule's threshold, a fraction of alpha (-),
            >= 0 (`SolverOptions`).
        solver: a Diffrax solver; default `diffrax.Tsit5()`.

    Returns:
        A `Response`. Check `response.status` (or `response.ok`): anything but
        `Status.SUCCESS` means the numbers are not final.

    Raises:
        ValueError: a `block`, `base` or `motion` of the wrong type or with
            batch axes, a `duration` or `history_step` that is not one
            number > 0, or a concrete option out of its range (the message
            names it).

    Examples:
        >>> import jaxrock as jr
        >>> r = jr.simulate(jr.Block(6.0, 1.0), jr.FixedBase(),
        ...                 jr.near_fault_pulse("Northridge JFA/SN"))
        >>> bool(r.ok), jr.Outcome(int(r.outcome)).name
        (True, 'ROCKING')
    """
    _check_single(block, base, motion)
    if duration is None:
        duration = motion.end_time + 5.0
    duration = one_real_number("duration", duration, "finite and > 0 (s)")
    positive("duration", duration)
    opts = SolverOptions.for_motion(
        motion, rtol, atol, max_steps, max_segments, rest_tolerance, solver
    )
    motion = motion.unlabeled()  # labels are static: they would recompile
    if not history:
        return _run_jit(block, base, motion, duration, opts)
    if history_step is None:
        history_step = min(float(duration) / 2000.0, 0.01)
    history_step = one_real_number("history_step", history_step, "finite and > 0 (s)")
    positive("history_step", history_step)
    c, hist = _history(block, base, motion.with_peaks(), duration, opts, history_step)
    result = response(c, block, opts)
    return eqx.tree_at(lambda r: r.history, result, hist, is_leaf=lambda x: x is None)


def _check_single(block, base, motion):
    """`simulate`'s inputs: one block, one base, one motion (batches of
    concrete values go to `behavior_map`, or `jax.vmap` over `simulate`)."""
    if not isinstance(block, Block):
        raise ValueError(f"`block` must be a jaxrock.Block, got {type(block).__name__}")
    check_base_and_motion(base, motion)
    for name, module in (("block", block), ("base", base), ("motion", motion)):
        shapes = (
            {module.batch_shape}
            if name == "motion"
            else {np.shape(x) for x in jax.tree_util.tree_leaves(module)}
        )
        if shapes - {()}:
            raise ValueError(
                f"`{name}` must hold one value per parameter in `simulate`, got "
                f"shapes {sorted(shapes)}: use `behavior_map` for batches, or "
                "`jax.vmap(simulate)`"
            )
