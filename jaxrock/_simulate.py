"""One analysis: the segment loop of a hybrid (event-driven) rocking simulation.

Each segment is one Diffrax solve of the vector field in one phase (translation,
rising, falling) until an event (uplift, apex, impact, rising again, overturn,
a new peak of |u|) or the end of the window; the loop then applies the
transition (the impact map at an impact) and starts the next segment. The loop
is a `lax.while_loop`, so `simulate` runs under `jit` and `vmap`: a finished
lane performs zero-length solves until every lane is done. With its history,
an analysis is one compiled program too (`_record`): the same loop, which
evaluates each segment's dense output at the history's sample times.

No program here holds a host callback, so that JAX's persistent cache keeps
them (it keeps no program that holds one): `diffeqsolve` gets its first step
from the step-size controller (`_FirstStep`), not as `dt0`, whose check
against t1 - t0 is an Equinox runtime check, a callback under Equinox's
default error mode; solver failures are statuses read from the solution
(`throw=False`), never errors raised at run time.
"""

import json
import threading

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from . import _cache
from ._block import Block
from ._dynamics import Phase, check_restitution, vector_field
from ._events import EVENT_ATOL, EVENT_RTOL, BracketedNewton
from ._free import free_rocking, free_rocking_ready
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator
from ._misc import check, flag, one_real_number
from ._model import (
    Carry,
    check_base_and_motion,
    initial_carry,
    is_active,
    lane_window,
    response,
    segment_setup,
    transition,
)
from ._results import (
    ATOL,
    MAX_SEGMENTS,
    RESPONSE_FIELDS,
    REST_TOLERANCE,
    RTOL,
    EventKind,
    History,
    Response,
    SolverOptions,
    Status,
)
from ._scene import closed_form_tail, prepare
from ._xla import compiler_accepts

# The most samples of a history (`simulate(..., history=True)`).
MAX_HISTORY_SAMPLES = 10_000_000


class _FirstStep(diffrax.AbstractAdaptiveStepSizeController):
    """`controller` with its first step `dt0` its own rather than
    `diffeqsolve`'s.

    `diffeqsolve` checks a `dt0` it is given against `t1 - t0` with
    `eqx.error_if`, which under `jit` is a host callback (with Equinox's
    default error mode), and JAX's persistent cache keeps no program that
    holds one: every process would compile `simulate` again. Given no `dt0`,
    `diffeqsolve` asks the controller for the first step, and this one
    answers with the same step (scaled by the direction of time, as
    `diffeqsolve` scales its `dt0`): the same steps, and no callback.
    """

    controller: diffrax.AbstractAdaptiveStepSizeController
    dt0: Array

    @property
    def rtol(self):
        return self.controller.rtol

    @property
    def atol(self):
        return self.controller.atol

    @property
    def norm(self):
        return self.controller.norm

    def wrap(self, direction):
        return _FirstStep(self.controller.wrap(direction), self.dt0 * direction)

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        del dt0
        return self.controller.init(
            terms, t0, t1, y0, self.dt0, args, func, error_order
        )

    def adapt_step_size(self, t0, t1, y0, y1, args, y_error, error_order, state):
        return self.controller.adapt_step_size(
            t0, t1, y0, y1, args, y_error, error_order, state
        )


class _FixedStep(diffrax.AbstractStepSizeController):
    """`diffrax.ConstantStepSize` with its step `dt0` its own (see
    `_FirstStep`: no host callback)."""

    dt0: Array
    controller: diffrax.ConstantStepSize = diffrax.ConstantStepSize()

    def wrap(self, direction):
        return _FixedStep(self.dt0 * direction, self.controller.wrap(direction))

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        del dt0
        return self.controller.init(
            terms, t0, t1, y0, self.dt0, args, func, error_order
        )

    def adapt_step_size(self, t0, t1, y0, y1, args, y_error, error_order, state):
        return self.controller.adapt_step_size(
            t0, t1, y0, y1, args, y_error, error_order, state
        )


def _solve_segment(c: Carry, block, base, motion, duration, opts, dense=False):
    """Integrate from c.t to the next event (or `duration`): a Diffrax solution."""
    active, args, conditions, t_stop, _, controller = segment_setup(
        c, block, base, motion, duration, opts
    )
    if opts.step is None:
        # The first step is the previous segment's mean step (no step-size
        # selection, which costs two evaluations a segment).
        root_finder = BracketedNewton(rtol=EVENT_RTOL, atol=EVENT_ATOL)
        controller = _FirstStep(controller, c.dt)
    else:
        root_finder, controller = None, _FixedStep(jnp.asarray(opts.step))
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
        dt0=None,
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
    """The whole analysis as one traceable function (for `jit`, `vmap`, `jacfwd`).

    Run until decided (`SolverOptions.until_decided`) on a base whose free
    rocking has a closed form, a block rocking below the separatrix once the
    ground is still is finished in closed form (`_free.py`), as maps finish
    it: its impacts down to rest are exact there, where an integration's
    tolerances, absolute and relative, lose the tail's tiny rotations."""

    def tail(c):
        """The analysis goes on in closed form from here."""
        if not closed_form_tail(block, base):
            return jnp.asarray(False)
        ready = free_rocking_ready(c, block, motion.end_time)
        return opts.until_decided & is_active(c, opts) & ready

    def cond(c):
        return is_active(c, opts) & ~tail(c)

    def body(c):
        sol = _solve_segment(c, block, base, motion, duration, opts)
        return transition(c, sol, block, base, motion, duration, opts)

    valid = opts.valid() & jnp.isfinite(duration) & (duration > 0)
    motion = prepare(motion)
    carry = jax.lax.while_loop(cond, body, initial_carry(block, base, motion, valid))
    if closed_form_tail(block, base):
        window = lane_window(motion, duration, opts)
        carry = free_rocking(carry, block, base, window, opts, tail(carry))
    return response(carry, block, base, opts)


_run_jit = eqx.filter_jit(run)


# Sample times evaluated per pass on a segment's dense output.
_WINDOW = 64


def _state(y) -> Array:
    """A state (theta, theta', base state) as one vector."""
    theta, theta_dot, base_state = y
    parts = [theta[None], theta_dot[None]]
    return jnp.concatenate(parts if base_state is None else [*parts, base_state])


def _regime(c: Carry):
    """0 in translation, else the rocking sign (`History.regime`)."""
    return jnp.where(c.phase == Phase.TRANSLATION, 0.0, c.sign)


def _record(block, base, motion, duration, opts: SolverOptions, grid):
    """`run`, recording the time histories: one program for the analysis and
    its history.

    Each segment's dense output is evaluated at the sample times `grid` (s,
    increasing, padded with inf) that lie inside it, `_WINDOW` at a time, and
    at its end; the state after the segment's transition is recorded too. The
    segments are those of `run`, with their dense output kept. A segment that
    is redone (`transition`) is recorded as its start, twice. Returns the
    `Response` and a dict of the recorded rows (`_history` orders them).
    """
    valid = opts.valid() & jnp.isfinite(duration) & (duration > 0)
    motion = prepare(motion)
    c0 = initial_carry(block, base, motion, valid)
    size = _state(c0.y).size
    # Each counted segment can follow a redo and the segment up to its limit,
    # which count none (`transition`): 3 passes a segment at most. Should the
    # rows run out, the analysis stops unfinished (MAX_SEGMENTS), never silently.
    passes = 3 * opts.max_segments + 1
    padded = jnp.concatenate([grid, jnp.full(_WINDOW, jnp.inf, grid.dtype)])
    rows = _empty_rows(padded, passes, size, c0.kind.dtype)

    def cond(state):
        c, k, _ = state
        return is_active(c, opts) & (k < passes)

    def body(state):
        c, k, rows = state
        sol = _solve_segment(c, block, base, motion, duration, opts, dense=True)
        new = transition(c, sol, block, base, motion, duration, opts)
        grid_y, grid_pass, end_y = _sampled(
            sol, grid, padded, c.t, new.t, k, rows["grid_y"], rows["grid_pass"]
        )
        rows = rows | dict(
            grid_y=grid_y,
            grid_pass=grid_pass,
            end_t=rows["end_t"].at[k].set(new.t),
            before_y=rows["before_y"].at[k].set(end_y),
            after_y=rows["after_y"].at[k].set(_state(new.y)),
            before_regime=rows["before_regime"].at[k].set(_regime(c)),
            after_regime=rows["after_regime"].at[k].set(_regime(new)),
            # (A redo, which sets a limit, is no event.)
            kind=rows["kind"]
            .at[k]
            .set(jnp.where(jnp.isfinite(new.t_limit), EventKind.END, new.kind)),
        )
        return new, k + 1, rows

    c, k, rows = jax.lax.while_loop(cond, body, (c0, jnp.asarray(0), rows))
    rows = rows | dict(
        passes=k,
        start_y=_state(c0.y),
        start_regime=_regime(c0),
        start_rocked=c0.rocked,
        start_t=c0.t + jnp.zeros((), grid.dtype),
        alpha=block.alpha,
    )
    return response(c, block, base, opts), _with_ground_and_z(
        rows, padded, base, motion
    )


def _empty_rows(padded, passes: int, size: int, kind_dtype) -> dict:
    """The recorded rows before the first segment: the states at the sample
    times `padded` and the pass that wrote each (-1: none), and per pass its
    end time, the states before and after its transition, their regimes and
    the event's kind."""
    dtype = padded.dtype
    return dict(
        grid_y=jnp.zeros((padded.size, size), dtype),
        grid_pass=jnp.full(padded.size, -1),
        end_t=jnp.zeros(passes, dtype),
        before_y=jnp.zeros((passes, size), dtype),
        after_y=jnp.zeros((passes, size), dtype),
        before_regime=jnp.zeros(passes, dtype),
        after_regime=jnp.zeros(passes, dtype),
        kind=jnp.zeros(passes, kind_dtype),
    )


def _sampled(sol, grid, padded, t0, t1, k, grid_y, grid_pass):
    """The segment's dense output `sol` (from t0 to t1, pass k) at the sample
    times of `grid` inside it, written into `grid_y` and `grid_pass`, and its
    state at t1, `_WINDOW` evaluations at a time."""
    size = grid_y.shape[1]
    first = jnp.searchsorted(grid, t0, side="right")
    stop = jnp.searchsorted(grid, t1, side="left")

    # Samples first..stop - 1 lie inside the segment; "sample" stop is its
    # end, t1 (one evaluation of the dense output in the program).
    def sample(inner):
        i, ys, at, end = inner
        index = i + jnp.arange(_WINDOW)
        ts = jax.lax.dynamic_slice(padded, (i,), (_WINDOW,))
        ts = jnp.clip(jnp.where(index == stop, t1, ts), t0, t1)
        new_ys = jax.vmap(lambda t: _state(sol.evaluate(t)))(ts)
        inside = (index >= first) & (index < stop)
        old_ys = jax.lax.dynamic_slice(ys, (i, 0 * i), (_WINDOW, size))
        old_at = jax.lax.dynamic_slice(at, (i,), (_WINDOW,))
        ys = jax.lax.dynamic_update_slice(
            ys, jnp.where(inside[:, None], new_ys, old_ys), (i, 0 * i)
        )
        at = jax.lax.dynamic_update_slice(at, jnp.where(inside, k, old_at), (i,))
        at_end = index == stop
        end = jnp.where(at_end.any(), new_ys[jnp.argmax(at_end)], end)
        return i + _WINDOW, ys, at, end

    start = (jnp.minimum(first, stop), grid_y, grid_pass, jnp.zeros(size, grid.dtype))
    _, grid_y, grid_pass, end_y = jax.lax.while_loop(
        lambda inner: inner[0] <= stop, sample, start
    )
    return grid_y, grid_pass, end_y


def _with_ground_and_z(rows: dict, padded, base, motion) -> dict:
    """The rows with x_g'' at every recorded time and, on a hysteretic base,
    the Bouc-Wen z of every recorded state."""
    times = jnp.concatenate([padded, rows["end_t"]])
    # Rows beyond the grid (padding) read the motion at t = 0, not at inf.
    rows["acceleration"] = jax.vmap(motion.acceleration)(
        jnp.where(jnp.isfinite(times), times, 0.0)
    )
    rows["start_acceleration"] = motion.acceleration(rows["start_t"])
    if base.hysteretic_state:
        states = jnp.concatenate([rows["grid_y"], rows["before_y"], rows["after_y"]])
        rows["z"] = jax.vmap(base.hysteretic)(states[:, 2:])
        rows["start_z"] = base.hysteretic(rows["start_y"][2:])
    return rows


# The programs of `_record` made in this process, by the structure and shapes
# of their arguments (see `_recording_program`).
_PROGRAMS: dict = {}
_PROGRAMS_LOCK = threading.Lock()


def _recording_program(treedef, specs):
    """`_record` for arguments of the structure `treedef` and the shapes
    `specs`, compiled: a function of the arguments' leaves. Made once per
    process; with jaxrock's cache folder the compiled program is kept there
    (`_cache.compiled`), and a later process loads it instead of tracing,
    lowering and compiling it."""
    key = (treedef, specs)
    with _PROGRAMS_LOCK:
        if key not in _PROGRAMS:
            _PROGRAMS[key] = _make_recording_program(treedef, specs)
        return _PROGRAMS[key]


def _make_recording_program(treedef, specs):
    def record(*leaves):
        result, rows = _record(*jax.tree_util.tree_unflatten(treedef, leaves))
        # Plain containers out: a kept program's output structure is pickled,
        # and a Module's would not read back.
        return {f: getattr(result, f) for f in RESPONSE_FIELDS}, rows

    options = _compiler_options()
    static = _cache.static_key(treedef)
    shapes = [(s.shape, str(s.dtype)) for s in specs]
    key = json.dumps([static, shapes, options])
    if static is None or len(jax.local_devices()) > 1:
        key = None  # not kept

    def lower():
        accepted = options if compiler_accepts(options) else {}
        return jax.jit(record, compiler_options=accepted).lower(*specs)

    return _cache.compiled("simulate", key, lower)


def _compiler_options() -> dict:
    """XLA's options for `_record`'s program: on the CPU, LLVM's optimization
    level 0. One analysis runs in milliseconds and compiles in seconds: at
    level 0 the program compiles in less time and runs in a few ms, and its
    results move in their last bits (docs/performance.md, "Start-up")."""
    if jax.default_backend() != "cpu":
        return {}
    return {"xla_backend_optimization_level": 0}


def _history(block, base, motion, duration, opts, step):
    """The analysis with its time histories, sampled every `step` (s) and at
    every event: the `Response` and its `History`.

    At an event both the state just before and just after the transition are
    recorded (same time). The samples are padded to a power of two (at least
    2048), so that analyses of other lengths reuse a handful of compiles.
    """
    duration, step = float(duration), float(step)
    grid = np.linspace(0.0, duration, int(np.ceil(duration / step - 1e-9)) + 1)
    size = max(2048, 1 << (grid.size - 1).bit_length())
    grid = np.pad(grid, (0, size - grid.size), constant_values=np.inf)
    args = (block, base, motion, np.float64(duration), opts, grid)
    leaves, treedef = jax.tree_util.tree_flatten(args)
    # Leaves as arrays of their own dtypes (not weakly typed): the program
    # compiled for their shapes takes them as they are.
    leaves = [jnp.asarray(np.asarray(x)) for x in leaves]
    specs = tuple(jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves)
    result, rows = _recording_program(treedef, specs)(*leaves)
    response = Response(**result)
    flight = int(response.status) == Status.FREE_FLIGHT
    return response, _history_rows(jax.device_get(rows), grid, flight)


def _history_rows(rows: dict, grid: np.ndarray, flight: bool = False) -> History:
    """The `History` of `_record`'s rows, in order: the start, then for each
    pass of the segment loop its samples, the state at its end and the state
    after its transition; with `flight` (the analysis ended FREE_FLIGHT), a
    last "flight" event at its end."""
    size, passes = rows["grid_y"].shape[0], int(rows["passes"])
    taken = np.flatnonzero(rows["grid_pass"] >= 0)
    ends = np.arange(passes)
    order = np.lexsort(
        (
            np.concatenate([[0], taken, 0 * ends, 0 * ends]),
            np.concatenate([[0], 0 * taken, 1 + 0 * ends, 2 + 0 * ends]),
            np.concatenate([[-1], rows["grid_pass"][taken], ends, ends]),
        )
    )

    def column(start, samples, before, after):
        parts = [np.asarray(start)[None], samples[taken], before[:passes]]
        return np.concatenate([*parts, after[:passes]])[order]

    grid = np.pad(grid, (0, size - grid.size), constant_values=np.inf)
    y = column(rows["start_y"], rows["grid_y"], rows["before_y"], rows["after_y"])
    sample_regime = rows["before_regime"][np.maximum(rows["grid_pass"], 0)]
    acceleration = rows["acceleration"]
    if "z" in rows:
        z = rows["z"]
        n = rows["end_t"].size
        z = column(rows["start_z"], z[:size], z[size : size + n], z[size + n :])
    else:
        z = np.zeros(y.shape[0])
    kinds = [EventKind(int(k)) for k in rows["kind"][:passes]]
    events = []
    regimes = zip(rows["before_regime"][:passes], rows["after_regime"][:passes])
    for t, k, (before, after) in zip(rows["end_t"], kinds, regimes):
        if k != EventKind.END:
            events.append((t, k))
        # An uplift in the transition of another event (a damped stop's push
        # at contact lifts the block at once) is an event too.
        if before == 0 and after != 0 and k != EventKind.UPLIFT:
            events.append((t, EventKind.UPLIFT))
    if rows["start_rocked"]:
        events.insert(0, (0.0, EventKind.UPLIFT))
    # g_eff reached 0 at another event (an uplift where the uplift level
    # falls to 0 with it), whose kind the pass holds.
    if flight and (not events or events[-1][1] != EventKind.FLIGHT):
        events.append((rows["end_t"][passes - 1], EventKind.FLIGHT))
    moving = y.shape[1] > 2  # a base with a state: u and u' lead it
    return History(
        t=column(rows["start_t"], grid, rows["end_t"], rows["end_t"]),
        theta=y[:, 0],
        theta_dot=y[:, 1],
        u=y[:, 2] if moving else np.zeros(y.shape[0]),
        u_dot=y[:, 3] if moving else np.zeros(y.shape[0]),
        z=z,
        regime=column(
            rows["start_regime"],
            sample_regime,
            rows["before_regime"],
            rows["after_regime"],
        ),
        ground_acceleration=column(
            rows["start_acceleration"],
            acceleration[:size],
            acceleration[size:],
            acceleration[size:],
        ),
        event_times=np.asarray([t for t, _ in events], dtype=float),
        event_kinds=tuple(k.name.lower() for _, k in events),
        alpha=float(rows["alpha"]),
    )


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
        duration: length of the analysis (s), one number > 0; default None:
            run until the block's fate is decided (it overturns, it rests and
            its base can no longer lift it, or on a fixed base once the
            ground is still it rocks below the separatrix and can no longer
            overturn), for at most `DECISION_WINDOW` (60 s) after the
            excitation; a fate still open then is `Status.UNDECIDED`.
        rtol: the integrator's relative tolerance (-). Events are located to
            about 1e-12 s on the dense output whatever the tolerances.
        atol: the integrator's absolute tolerance, in the state's units (rad,
            rad/s, m, m/s).
        history: also return the time histories (`Response.history`), from
            one compiled program for the analysis and its history (concrete
            inputs only: not under `jit`, `vmap` or `jacfwd`).
        history_step: spacing of the history's samples (s), one number of
            at least the window / 10,000,000; every event is recorded as
            well. Default: duration / 2000, at most 0.01 s.
        max_steps: the solver's step limit in one segment; default 16384,
            raised for long records to 4 steps a sample (a guard against
            runaway solves that a valid record never reaches).
        max_segments: the limit on segments (events) of the analysis; default
            2000.
        rest_tolerance: the rest rule's threshold, a fraction of alpha (-),
            in [0, 0.01] (`SolverOptions`).
        solver: a Diffrax solver; default `diffrax.Tsit5()`.

    Returns:
        A `Response`. Check `response.status` (or `response.ok`): anything but
        `Status.SUCCESS` means the numbers are not final.

    Raises:
        ValueError: a `block`, `base` or `motion` of the wrong type or with
            batch axes, a `duration` or `history_step` that is not one
            number > 0, a `history_step` without `history`, or a concrete
            option out of its range (the message names it).

    Examples:
        >>> import jaxrock as jr
        >>> r = jr.simulate(jr.Block(6.0, 1.0), jr.FixedBase(),
        ...                 jr.near_fault_pulse("Northridge JFA/SN"))
        >>> bool(r.ok), jr.Outcome(int(r.outcome)).name
        (True, 'ROCKING')
    """
    _check_single(block, base, motion)
    duration, opts = SolverOptions.for_analysis(
        motion,
        duration,
        rtol=rtol,
        atol=atol,
        max_steps=max_steps,
        max_segments=max_segments,
        rest_tolerance=rest_tolerance,
        solver=solver,
    )
    motion = motion.unlabeled()  # labels are static: they would recompile
    if not flag("history", history):
        if history_step is not None:
            raise ValueError("`history_step` is read only with `history=True`")
        return _run_jit(block, base, motion, duration, opts)
    history_step = _history_step(history_step, float(duration))
    result, hist = _history(block, base, motion, duration, opts, history_step)
    return eqx.tree_at(lambda r: r.history, result, hist, is_leaf=lambda x: x is None)


def _history_step(history_step, duration: float) -> float:
    """`simulate`'s `history_step` (default: duration / 2000, at most 0.01 s),
    checked: one number of at least duration / `MAX_HISTORY_SAMPLES` (the
    history's rows are kept in memory, about 100 bytes each)."""
    if history_step is None:
        return min(duration / 2000.0, 0.01)
    history_step = one_real_number("history_step", history_step, "finite and > 0 (s)")
    shortest = duration / MAX_HISTORY_SAMPLES
    check(
        "history_step",
        history_step,
        lambda v: v >= shortest,
        f">= the window / {MAX_HISTORY_SAMPLES:,} ({shortest:.3g} s)",
    )
    return history_step


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
    check_restitution(block, base)
