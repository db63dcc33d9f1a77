"""The flat loop of behavior maps: one solver step per iteration, events inside.

A vmapped loop costs its slowest lane at every iteration. With one Diffrax solve
per segment (`simulate`), an iteration lasts as long as the longest segment of
any lane, and segments are short and uneven (uplift, apex, impact, new peaks of
|u|): about half the executed lane-steps were waiting, and each segment paid a
solve's set-up. Here an iteration advances every lane by one step attempt of
the same solver and step-size controller (Tsit5 and `StepSizeController` by
default);
the same event conditions are checked at the step's end, an event is located
on the step's dense output by bracketed Newton, and `transition` applies it
exactly as in the segment loop. `_chunk.map_chunk` refills finished lanes.
For speed on small systems the Runge-Kutta stages are unrolled (`_erk_step`).
Most steps end with no event: their lanes only move on (`move_on`), and only
the others (an event, a segment's end) run the root find and `transition`,
gathered in batches (`flat_step`).
"""

import functools

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._controller import KinkClip
from ._dynamics import Args, Phase, rest_level, vector_field
from ._events import EVENT_ATOL, EVENT_RTOL, newton_in_bracket
from ._isolators import AbstractIsolator
from ._layout import Loop, loop_for
from ._misc import GRAVITY, computed_once, is_none, where_lanes
from ._model import (
    Conditions,
    event_conditions,
    is_active,
    move_on,
    moves_on,
    quiet_end,
    quiet_level,
    redo_limit,
    segment_end,
    segment_setup,
    transition,
    with_start_conditions,
)
from ._scene import fixed_base, has_vertical, rest_jumps, rocking_reads_all
from ._signal import (
    AbstractAcceleration,
    StillGround,
    accelerations_at,
    gravities_at,
)

# Newton iterations of an event's root find (kept in a bracket, from the secant
# guess). 8 reproduce the paper's maps to 3e-14 against 14; 5 are too few (near
# double roots of theta' the bracket falls back to bisection).
_NEWTON = 8
# ... or fewer: a step below a few ulps of t has converged (quadratically: the
# next would not move it).
_CONVERGED = 4 * float(np.finfo(np.float64).eps)


def _unrollable(solver) -> bool:
    """An explicit Runge-Kutta method given by a Butcher tableau."""
    return isinstance(solver, diffrax.AbstractERK) and solver.tableau.c1 == 0


def _stage_times(tableau, t0, t1):
    """The times of an explicit Runge-Kutta step's stages, t0 + c_i h."""
    h = t1 - t0
    return [t0] + [t0 + c * h for c in tableau.c]


class _Known(AbstractAcceleration):
    """The ground's acceleration (and g_eff) at one time, already computed:
    what a stage of `_erk_step` or a condition at a step's end reads of the
    motion (read at all of a step's times together in `_attempt`:
    `step_accelerations`, `step_gravities`)."""

    value: jax.Array
    known_gravity: jax.Array | float = GRAVITY

    def acceleration(self, t):
        return jnp.broadcast_to(self.value, jnp.shape(t))

    def gravity(self, t):
        if isinstance(self.known_gravity, float):
            return self.known_gravity
        return jnp.broadcast_to(self.known_gravity, jnp.shape(t))


def _with_ground(args: Args, value, gravity=GRAVITY) -> Args:
    return eqx.tree_at(lambda a: a.motion, args, _Known(value, gravity))


def _erk_step(tableau, t0, t1, y0, args, ground=None, gravity=None):
    """One step of an explicit Runge-Kutta method, its stages unrolled.

    The same arithmetic as Diffrax's `AbstractERK.step` (which runs the stages in
    a while loop: on the CPU the loop's overhead cost more than the stages of
    this small system). `ground` holds x_g'' at the stage times
    (`_stage_times`; None: read from `args.motion`) and `gravity` g_eff
    there (None: g). Returns y1, the error
    estimate and Diffrax's dense information (y0, y1 and the stage increments
    k_i = h f(t_i, y_i)). The base states past the isolator's `n_integrated`
    (zero rates) are carried through the stages as they are: the same
    numbers as their sums of zero increments, without the sums.
    """
    h = t1 - t0
    times = _stage_times(tableau, t0, t1)
    if ground is None:
        ground = [args.motion.acceleration(t) for t in times]
    if gravity is None:
        gravity = [GRAVITY] * len(times)
    n = args.base.n_integrated
    held = n is not None and n < args.base.n_states

    def increment(i, y):
        f = vector_field(times[i], y, _with_ground(args, ground[i], gravity[i]))
        k = jax.tree_util.tree_map(lambda v: h * v, f)
        return (k[0], k[1], k[2][:n]) if held else k

    def combine(y, weights, ks):
        def add(y, *k):
            return sum((w * kj for w, kj in zip(weights, k) if w != 0), y)

        if not held:
            return jax.tree_util.tree_map(add, y, *ks)
        base = add(y[2][:n], *(k[2] for k in ks))
        thetas = jax.tree_util.tree_map(add, y[:2], *(k[:2] for k in ks))
        return (*thetas, jnp.concatenate([base, y[2][n:]]))

    ks = [increment(0, y0)]
    for i, a in enumerate(tableau.a_lower, start=1):
        ks.append(increment(i, combine(y0, a, ks)))
    y1 = combine(y0, tableau.b_sol, ks)
    y_error = combine(jax.tree_util.tree_map(jnp.zeros_like, y0), tableau.b_error, ks)
    if held:  # the held states' increments: h 0 = 0
        zeros = jnp.zeros_like(y0[2][n:])
        ks = [(k[0], k[1], jnp.concatenate([k[2], zeros])) for k in ks]
    k = jax.tree_util.tree_map(lambda *k: jnp.stack(k), *ks)
    return y1, y_error, dict(y0=y0, y1=y1, k=k)


class _StepSolution:
    """What `transition` reads of a Diffrax solution, for one step."""

    def __init__(self, t, y, result, event_mask, steps):
        self.ts = t[None]
        self.ys = jax.tree_util.tree_map(lambda x: x[None], y)
        self.result = result
        self.event_mask = event_mask
        self.stats = {"num_steps": steps}


class _Attempt(eqx.Module):
    """One lane's step attempt, before its event (if any) is located."""

    t0: jax.Array
    t1: jax.Array
    y0: tuple
    y1: tuple
    keep: jax.Array  # the controller accepted the step
    crossed: tuple  # per condition: it went from > 0 to <= 0 in the step
    fired: tuple  # per condition: this one ends the step (the first in order)
    g0: jax.Array  # the fired condition at t0 (> 0) and at t1 (<= 0)
    g1: jax.Array
    dense: dict
    args: Args
    ends: tuple | None  # every condition at t1 (with `Carry.start_conditions`)
    next_dt: jax.Array
    next_t0: jax.Array  # the next step's start, and its end as the controller
    proposed: jax.Array  # proposes it (before it ends at a kink)
    failed: jax.Array
    moves_on: jax.Array  # no event, no segment end: `move_on` ends the step
    searches: jax.Array  # a lane at rest looks for a jump (`_rest_jump`)

    @property
    def event(self):
        return sum(self.fired, jnp.asarray(False)) > 0


def _solver_step(solver, term, t0, t1, y0, args, motion):
    """One step of `solver` from (t0, y0) to t1: (y1, the error estimate, the
    dense information, the solver's result, and the vector field's arguments
    at t0 and at t1). An explicit Runge-Kutta method reads x_g'' and g_eff
    at its stage times and at t1 together, and runs unrolled (`_erk_step`;
    a method whose stages leave [t0, t1] reads them as any times)."""
    if not _unrollable(solver):
        state = solver.init(term, t0, t1, y0, args)
        y1, y_error, dense, _, result = solver.step(
            term, t0, t1, y0, args, state, made_jump=False
        )
        return y1, y_error, dense, result, args, args
    times = _stage_times(solver.tableau, t0, t1) + [t1]
    within = all(0 <= c <= 1 for c in solver.tableau.c)
    if within:
        ground = motion.step_accelerations(times)
    else:
        ground = accelerations_at(motion, times)
    gravity = [GRAVITY] * len(times)
    if has_vertical(motion):
        gravity = (
            motion.step_gravities(times) if within else gravities_at(motion, times)
        )
    args0 = _with_ground(args, ground[0], gravity[0])
    args1 = _with_ground(args, ground[-1], gravity[-1])
    y1, y_error, dense = _erk_step(solver.tableau, t0, t1, y0, args, ground, gravity)
    y1, y_error = computed_once((y1, y_error))  # read by most of the step
    return y1, y_error, dense, diffrax.RESULTS.successful, args0, args1


def _crossings(conditions, starts, keep, start, end):
    """The event conditions over a step from `start` to `end` ((t, y, args)
    each): per condition, whether it went from > 0 to <= 0 (`crossed`, in a
    kept step) and whether it ends the step (`fired`: the first in order to
    cross); whether any did, the fired one's values at the two ends, and
    every condition at the end. At the start they are `starts` where the
    carry has them (the end of the last step), else evaluated."""
    crossed, fired, before = [], [], jnp.asarray(False)
    g0 = g1 = jnp.zeros_like(start[0])
    ends = []
    for i, cond in enumerate(jax.tree_util.tree_leaves(conditions)):
        v0 = cond(*start) if starts is None else starts[i]
        v1 = cond(*end)
        ends.append(v1)
        crossed.append(keep & (v0 > 0) & (v1 <= 0))
        hit = crossed[-1] & ~before
        fired.append(hit)
        before = before | hit
        g0, g1 = jnp.where(hit, v0, g0), jnp.where(hit, v1, g1)
    return tuple(crossed), tuple(fired), before, g0, g1, tuple(ends)


def _attempt(c, block, base, motion, duration, opts) -> _Attempt:
    """One step attempt of one lane, and the conditions at its ends."""
    active, args, conditions, t_stop, dtmax, controller = segment_setup(
        c, block, base, motion, duration, opts
    )
    dtmax = jnp.inf if dtmax is None else dtmax
    term = diffrax.ODETerm(vector_field)
    solver = opts.solver
    t0, y0 = c.t, c.y
    dt = jnp.minimum(c.dt, dtmax)
    # (A block at rest: where |x_g''| may reach its uplift level, carried.)
    level = quiet_level(c, block, base, motion)
    kinks = motion.limits_steps(level is not None)
    kink = motion.next_kink(t0, level, c.quiet_end) if kinks else None
    t1 = t0 + dt if kink is None else motion.step_end(t0, dt, kink)
    t1 = jnp.minimum(t1, t_stop)
    t1 = jnp.where(active, t1, t0 + 1.0)  # a frozen lane: a harmless dummy step
    step = _solver_step(solver, term, t0, t1, y0, args, motion)
    y1, y_error, dense, solver_result, args0, args1 = step
    # The controller's next step, before it ends at a kink (`KinkClip`): the
    # next attempt ends it there (`step_end`). (`StepSizeController` keeps no
    # state between steps.)
    pid = controller.controller if isinstance(controller, KinkClip) else controller
    keep, next_t0, proposed, _, _, ctrl_result = pid.adapt_step_size(
        t0, t1, y0, y1, args, y_error, solver.error_order(term), None
    )
    # A block at rest whose quiet stretch ended without an uplift (it rested
    # while |x_g''| was above its level) finds its next one in `_finish`.
    stale = jnp.asarray(False)
    if c.quiet_end is not None:
        stale = (level > 0) & ~motion.quiet_holds(next_t0, c.quiet_end)
    starts = c.start_conditions
    crossed, fired, before, g0, g1, ends = _crossings(
        conditions, starts, keep, (t0, y0, args0), (t1, y1, args1)
    )
    failed = (solver_result != diffrax.RESULTS.successful) | (
        ctrl_result != diffrax.RESULTS.successful
    )
    next_dt = jnp.where(active, proposed - next_t0, c.dt)
    t_end = jnp.where(keep, t1, t0)
    base_end = None if y0[2] is None else jnp.where(keep, y1[2], y0[2])
    moving = moves_on(c, t_end, base_end, failed, base, motion, duration, opts)
    searches = jnp.asarray(False)
    if rest_jumps(motion):
        k, exact = motion.sample_at(t0)
        resting = active & (c.phase == Phase.TRANSLATION)
        searches = resting & exact & (k >= c.search_from)
    plain = ~before & ~stale & ~searches & moving
    return _Attempt(
        t0,
        t1,
        y0,
        y1,
        keep,
        crossed,
        fired,
        g0,
        g1,
        dense,
        args,
        None if starts is None else ends,
        next_dt,
        next_t0,
        proposed,
        failed,
        plain,
        searches,
    )


# Tsit5's dense output weights in monomials of s = (t - t0) / h:
# b_i(s) = sum_m W[i, m - 1] s^m, m = 1..4 (b_i(0) = 0): the Taylor coefficients
# at s = 0 of Diffrax's own interpolant (tests/test_flat.py checks them against
# it). Constants, not computed while a map is traced: that took about a hundred
# small compiles in every process.
_TSIT5_WEIGHTS = np.array(
    [
        [
            0.9999999999999998,
            -2.763706197274826,
            2.913255461821912,
            -1.0530884977290216,
        ],
        [0.0, 0.13169999999999998, -0.22339999999999996, 0.1017],
        [0.0, 3.930296236894751, -5.941033872131505, 2.490627285651253],
        [0.0, -12.411077166933676, 30.33818863028232, -16.548102889244902],
        [0.0, 37.50931341651104, -88.1789048947664, 47.379521962819275],
        [0.0, -27.896526289197286, 65.09189467479366, -34.87065786149661],
        [0.0, 1.5, -4.0, 2.5],
    ]
)


def _dense_weights(solver) -> np.ndarray | None:
    """The weights W of a solver's dense output in monomials of s (stages x
    degree: b_i(s) = sum_m W[i, m - 1] s^m), or None: another interpolant,
    evaluated as Diffrax does. Dopri8's is Diffrax's own table (a sextic in
    s), its columns reversed."""
    if isinstance(solver, diffrax.Tsit5):
        return _TSIT5_WEIGHTS
    if isinstance(solver, diffrax.Dopri8):
        return np.asarray(solver.interpolation_cls.eval_coeffs)[:, ::-1]
    return None


def _dense_in_s(solver, a: "_Attempt"):
    """The step's dense output as a function of s = (t - t0) / (t1 - t0).

    Tsit5's is a quartic in s, Dopri8's a sextic (`_dense_weights`): their
    coefficients are computed once, and each evaluation is Horner's rule
    (elementwise: cheap inside Newton's iterations), where Diffrax's
    interpolation object rebuilds them at each evaluation (the docs'
    performance page, "Choices in the code").
    """
    weights = _dense_weights(solver)
    if weights is None:
        evaluate = solver.interpolation_cls(t0=a.t0, t1=a.t1, **a.dense).evaluate
        return lambda s: evaluate(a.t0 + s * (a.t1 - a.t0))

    def coefficients(k):
        return jnp.stack(
            [
                sum(w * k[i] for i, w in enumerate(column) if w != 0)
                for column in weights.T
            ]
        )

    y0 = a.dense["y0"]
    c = computed_once(jax.tree_util.tree_map(coefficients, a.dense["k"]))

    def evaluate(s):
        def horner(y, c):
            p = c[-1]
            for cm in c[-2::-1]:
                p = cm + s * p
            return y + s * p

        return jax.tree_util.tree_map(horner, y0, c)

    return evaluate


def _locate(a: _Attempt, opts, unfired=()):
    """The event's time and state: bracketed Newton on [t0, t1] (the condition is
    > 0 at t0 and <= 0 at t1) on the step's dense output, from the secant.

    Also returns whether Newton converged within `_NEWTON` iterations, the
    bracket's upper end (the condition <= 0 there), and where a redo ends if
    another condition that crossed in the step did so first (`redo_limit`;
    inf: none). From a poor start (a root close to t0 in a long step, where
    the secant is far off) Newton may not converge: the lane then retries a
    shorter step (see `_finish`). Conditions whose index is
    in `unfired` fired in no lane of the batch and are not evaluated.

    Newton runs in s = (t - t0) / h on the dense output in s (a quartic in s
    for Tsit5), `_NEWTON` iterations in a loop (a lane stops moving once
    converged). Unrolled, they run no faster, on any base (a friction
    pendulum's conditions too, which read its z), and the loop compiles in
    1.3-1.5 times as long.
    """
    # The conditions of the attempt, one per entry of `fired` (the batch's
    # stand-ins for the ground and the base keep the same conditions).
    conditions = jax.tree_util.tree_leaves(
        event_conditions(a.args.block, a.args.base, a.args.motion)
    )
    if len(conditions) != len(a.fired):
        raise AssertionError(f"{len(conditions)} conditions, {len(a.fired)} fired")
    evaluate = _dense_in_s(opts.solver, a)
    h = a.t1 - a.t0

    def g(s):
        t, y = a.t0 + s * h, evaluate(s)
        return sum(
            jnp.where(hit, cond(t, y, a.args), 0.0)
            for i, (hit, cond) in enumerate(zip(a.fired, conditions))
            if i not in unfired
        )

    lower, upper = jnp.zeros_like(h), jnp.ones_like(h)
    s = jnp.clip(a.g0 / jnp.where(a.g0 == a.g1, 1.0, a.g0 - a.g1), 0.0, 1.0)
    step = jnp.full_like(h, jnp.inf)  # of s

    def iteration(_, state):
        s, lower, upper, step = state
        going = step * h > _CONVERGED * jnp.abs(a.t0 + s * h)
        # Computed once, then read by the four outputs (XLA copies g, the
        # iteration's cost, into each output that reads it).
        value, slope = computed_once(jnp.stack(jax.jvp(g, (s,), (jnp.ones_like(s),))))
        new, new_lower, new_upper = newton_in_bracket(
            s, value, slope, lower, upper, True
        )
        lower = jnp.where(going, new_lower, lower)
        upper = jnp.where(going, new_upper, upper)
        step = jnp.where(going, jnp.abs(new - s), step)
        s = jnp.where(going, new, s)
        # One kernel writes an iteration's state, and the next reads it (else
        # XLA recomputes earlier iterations inside later ones).
        return tuple(computed_once(jnp.stack([s, lower, upper, step])))

    s, lower, upper, step = jax.lax.fori_loop(
        0, _NEWTON, iteration, (s, lower, upper, step)
    )
    t, y = a.t0 + s * h, evaluate(s)
    # Located as `simulate` locates events; else the lane retries (`_finish`).
    converged = step * h <= EVENT_RTOL * jnp.abs(t) + EVENT_ATOL
    # The other conditions that crossed in the step, at its start and at the
    # event: did one cross first (see `transition`)?
    candidates, values = [], []
    for i, (crossed, fired, cond) in enumerate(zip(a.crossed, a.fired, conditions)):
        if i not in unfired:
            candidates.append(crossed & ~fired)
            values.append((cond(a.t0, a.y0, a.args), cond(t, y, a.args)))
    limit = redo_limit(a.t0, t, candidates, *zip(*values))
    return t, y, converged, a.t0 + upper * h, limit


def _finish(c, a: _Attempt, located, jump, block, base, motion, duration, opts):
    """The lane's new carry: the step's end, or the event and its transition,
    or `jump`'s end (None: no lane jumps); its next step is `_look_ahead`'s."""
    t_event, y_event, converged, upper, limit = located
    retry = a.event & ~converged
    event = a.event & converged
    keep = a.keep & ~retry
    t_end = jnp.where(event, t_event, jnp.where(keep, a.t1, a.t0))
    y_end = jax.tree_util.tree_map(
        lambda a1, a0, e: jnp.where(event, e, jnp.where(keep, a1, a0)),
        a.y1,
        a.y0,
        y_event,
    )
    if jump is not None:
        t_end = jnp.where(jump.go, jump.t, t_end)
        y_end = (*y_end[:2], jnp.where(jump.go, jump.base_state, y_end[2]))
    result = diffrax.RESULTS.where(
        event, diffrax.RESULTS.event_occurred, diffrax.RESULTS.successful
    )
    result = diffrax.RESULTS.where(a.failed, diffrax.RESULTS.internal_error, result)
    sol = _StepSolution(t_end, y_end, result, a.fired, jnp.asarray(1))
    # (A redo needs an event: `limit` of other lanes is unused.)
    new = transition(c, sol, block, base, motion, duration, opts, limit)
    if jump is not None:
        searched = jnp.where(a.searches, jump.search_from, c.search_from)
        new = eqx.tree_at(
            lambda n: (n.max_u, n.search_from),
            new,
            (
                jnp.where(jump.go, jnp.maximum(new.max_u, jump.max_u), new.max_u),
                jnp.where(event, 0.0, searched),
            ),
        )
    return with_start_conditions(new, block, base, motion)


# A lane at rest whose search found no jump searches again this many samples
# later.
_SEARCH_AGAIN = 16


class _Jump(eqx.Module):
    """A lane at rest on an isolated base that skips samples (`_rest_jump`):
    whether it does (`go`), to where (t, its base state, max |u| there) and
    the sample where it searches next (`Carry.search_from`)."""

    go: jax.Array
    t: jax.Array
    base_state: jax.Array
    max_u: jax.Array
    search_from: jax.Array


def _rest_jump(c, a: _Attempt, block, base, motion, duration, opts) -> _Jump:
    """A lane at rest at sample k on a linear isolator, under a record with
    translation tables (`_scene.rest_jumps`), jumps to the first sample
    interval m over which the block could uplift or |u| reach a new maximum,
    if m >= k + 2.

    The base state is y = y_p + h: y_p tabulated, h a free vibration (exact,
    `free_vibration`) whose bounds (`free_vibration_bounds`) lower the
    levels: |A| <= max |A_p| + max |A_h| stays below the uplift level, and
    |u| <= max |u_p| + max |u_h| below max |u| so far. A lane that never
    rocked moves on y_p itself (h = 0, its state from t = 0), and max |u|
    over the jump is read from the table.
    """
    k, _ = motion.sample_at(a.t0)
    k = k.astype(int)
    h = jnp.where(c.rocked, a.y0[2] - motion.translation_state(k), 0.0)
    u_bound, f_bound = base.free_vibration_bounds(h)
    margin = 1.0 - 1e-9  # rounding
    acceleration = rest_level(block, c.slid, motion.least_gravity) * margin - f_bound
    displacement = jnp.where(c.rocked, c.max_u * margin - u_bound, jnp.inf)
    m = motion.translation_first(k, acceleration, displacement)
    t = motion.sample_time(m)
    _, t_stop = segment_end(c, motion, duration, opts)
    go = a.searches & (m >= k + 2) & ~a.event & (t <= jnp.minimum(t_stop, c.t_limit))
    state = motion.translation_state(m) + base.free_vibration(h, t - a.t0)
    max_u = jnp.where(c.rocked, c.max_u, motion.translation_displacement_max(m))
    again = jnp.where(go, m + 1, k + _SEARCH_AGAIN).astype(a.t0.dtype)
    return _Jump(go, t, state, max_u, again)


def _quiet_end_afresh(a: _Attempt, new, block, base, motion):
    """A block at rest on a fixed base: where |x_g''| may next reach its
    uplift level, from the event where it comes to rest, else from the next
    step's start (as a block at rest looks ahead)."""
    resting = new.phase == Phase.TRANSLATION
    t = jnp.where(resting, new.t, a.next_t0)
    return quiet_end(t, block, base, motion, new.slid)


def _look_ahead(a: _Attempt, located, new):
    """The lane's next step (`new.dt`): the controller's proposal (not the mean
    step of a segment), which the next attempt ends at its kink (`step_end`).
    An event whose root find did not converge rejects the step, and the next
    attempt is at most half as long, ending at or before the bracket's upper
    end (so each retry gets closer to the root)."""
    _, _, converged, upper, _ = located
    retry = a.event & ~converged
    retry_dt = jnp.minimum(upper - a.t0, 0.5 * (a.t1 - a.t0))
    return eqx.tree_at(lambda n: n.dt, new, jnp.where(retry, retry_dt, a.next_dt))


# Lanes whose events are located together (a batch of the root find): 8, as
# many as end a step in most iterations of a CPU's 64 lanes (a larger batch
# makes every lane that moves on pay for the root find). On a base with a
# hysteretic state, whose events are costly (their conditions read z) and
# rarer, 4. The timings behind both: the docs' performance page, "Choices in
# the code".
_BATCH, _BATCH_HYSTERETIC = 8, 4


def _batch_size(lanes: int, base: AbstractIsolator) -> int:
    return min(_BATCH_HYSTERETIC if base.hysteretic_state else _BATCH, lanes)


class _ForceFree(AbstractIsolator):
    """An isolated base without its force: what the root find of rocking lanes
    reads of it (their conditions are the block's angles, the base's u and
    u'; the force, a friction pendulum's z among it, enters only the uplift
    conditions of pure translation). It keeps the base's `capacity` and
    `stop`, whose event condition reads u."""

    base: AbstractIsolator

    @property
    def n_states(self):
        return self.base.n_states

    def initial_state(self):
        return self.base.initial_state()

    def force(self, state):
        return jnp.zeros_like(state[0])

    def rates(self, state, u_ddot):
        return self.base.rates(state, u_ddot)

    @property
    def block_mass_fraction(self):
        return self.base.block_mass_fraction

    def peak_condition(self):
        return self.base.peak_condition()

    def free_vibration_bounds(self, state):
        return self.base.free_vibration_bounds(state)


def _locate_batch(sub: _Attempt, valid, opts, motion, motion_axes):
    """`_locate` on a batch of lanes (leading axis; `valid`: real lanes).

    `sub.args.motion` is None: the lanes' motion is `motion`, batched as
    `motion_axes` says (None: one motion of every lane, a record, which is
    never copied into the lanes: gathered per lane it cost more than the step).

    Most batches need less than every condition, and one `lax.cond` a batch
    picks a cheaper Newton loop (the same results, bit for bit):
    - on a fixed base only the uplift conditions (pure translation) read the
      ground motion: a batch in which every lane rocks locates with a still
      motion (a batch: 27 kernels instead of 78);
    - likewise on an isolator the force (and a friction pendulum's z, costly
      in closed form) enters only the uplift conditions, and "quiet" (the
      base's free-vibration bounds, armed in translation only) too: a batch in
      which every lane rocks evaluates neither;
    - but a block's slide condition (`rocking_reads_all`) reads both, and
      the free flight of a vertical motion reads g_eff (`StillGround` keeps it).
    """

    def locate(sub, motion, axes, unfired=()):
        def one(a, motion):
            a = eqx.tree_at(lambda a: a.args.motion, a, motion, is_leaf=is_none)
            return _locate(a, opts, unfired)

        return jax.vmap(one, in_axes=(0, axes))(sub, motion)

    translating = jnp.any(valid & (sub.args.phase == Phase.TRANSLATION))
    if rocking_reads_all(sub.args.block):
        return locate(sub, motion, motion_axes)
    if fixed_base(sub.args.base):
        vertical = has_vertical(motion)
        still = (
            (StillGround(motion), StillGround(motion_axes))
            if vertical
            else (StillGround(), None)
        )
        return jax.lax.cond(
            translating,
            lambda: locate(sub, motion, motion_axes),
            lambda: locate(sub, *still),
        )
    base = sub.args.base
    free = _ForceFree(base, capacity=base.capacity, stop=base.stop)
    rocking = eqx.tree_at(lambda s: s.args.base, sub, free)
    quiet = Conditions._fields.index("quiet")
    return jax.lax.cond(
        translating,
        lambda: locate(sub, motion, motion_axes),
        lambda: locate(rocking, motion, motion_axes, unfired=(quiet,)),
    )


def _take_lanes(tree, axes, index):
    """The lanes `index` of `tree`, batched as `axes` says (a vmap `in_axes`
    prefix: 0 or None, or a pytree of them): unbatched leaves are kept."""
    if axes is None:
        return tree
    if axes == 0:
        return jax.tree_util.tree_map(lambda x: x[index], tree)
    return jax.tree_util.tree_map(
        lambda ax, x: x if ax is None else x[index], axes, tree, is_leaf=is_none
    )


def _moved(c, a: _Attempt, block, base, motion, in_axes):
    """The carries of the lanes whose step only moves them on (`move_on`,
    elementwise; the others are replaced in `flat_step`)."""
    y_end = where_lanes(a.keep, a.y1, a.y0)
    starts = quiet_now = None
    if a.ends is not None:  # the conditions at the step's end start the next
        starts = tuple(
            jnp.where(a.keep, v1, v0) for v1, v0 in zip(a.ends, c.start_conditions)
        )
        quiet_now = starts[Conditions._fields.index("quiet")]
    moved = jax.vmap(move_on, in_axes=(0, 0, 0) + in_axes + (0,))(
        c, jnp.where(a.keep, a.t1, a.t0), y_end, block, base, motion, quiet_now
    )
    moved = eqx.tree_at(lambda m: m.dt, moved, a.next_dt)
    if starts is not None:
        moved = eqx.tree_at(lambda m: m.start_conditions, moved, starts)
    return moved


def _rest_jumps(sub_c, sub: _Attempt, valid, motion, motion_axes, duration, opts):
    """`_rest_jump` of a batch's lanes (None: the scene has no
    `rest_jumps`), computed only if one of them searches."""
    if not rest_jumps(motion):
        return None
    jumps = jax.vmap(_rest_jump, in_axes=(0, 0, 0, 0, motion_axes, None, None))
    block, base = sub.args.block, sub.args.base
    return jax.lax.cond(
        jnp.any(sub.searches & valid),
        lambda: jumps(sub_c, sub, block, base, motion, duration, opts),
        lambda: _Jump(
            jnp.zeros_like(sub.searches),
            sub.t0,
            sub.y0[2],
            sub_c.max_u,
            sub_c.search_from,
        ),
    )


def _end_lanes(sub_c, sub: _Attempt, valid, motion, motion_axes, duration, opts):
    """The new carries of a batch of lanes whose step does not only move on
    (`valid`: real lanes; `motion` batched as `motion_axes` says): their
    events located, jumps, transitions, and next steps."""
    located = _locate_batch(sub, valid, opts, motion, motion_axes)
    block, base = sub.args.block, sub.args.base
    jump = _rest_jumps(sub_c, sub, valid, motion, motion_axes, duration, opts)
    new = jax.vmap(_finish, in_axes=(0, 0, 0, 0, 0, 0, motion_axes, None, None))(
        sub_c, sub, located, jump, block, base, motion, duration, opts
    )
    if sub_c.quiet_end is not None:
        # Where the next attempt may end (`step_end`), searched only where a
        # lane rests before or after its step (a rocking lane's `quiet_end` is
        # never read): `quiet_end` of the step's start may no longer hold.
        rest = Phase.TRANSLATION
        rests = (sub_c.phase == rest) | (new.phase == rest)
        found = jax.lax.cond(
            jnp.any(rests & valid),
            lambda: jax.vmap(_quiet_end_afresh, in_axes=(0, 0, 0, 0, motion_axes))(
                sub, new, block, base, motion
            ),
            lambda: sub_c.quiet_end,
        )
        new = eqx.tree_at(lambda n: n.quiet_end, new, found)
    return jax.vmap(_look_ahead)(sub, located, new)


def flat_step(
    c, block, base, motion, duration, opts, in_axes, loop: Loop | None = None
):
    """One step attempt of every lane (leading axis); returns the new carries
    and the attempts (`_Attempt`, before their events were located).

    `block`, `base` and `motion` are batched as `in_axes` says. Most steps end
    with no event and before their segment's end: their lanes only move on
    (`_moved`, elementwise). The others (an event, a segment's end, a
    failure, a search for a jump) are gathered in batches (`_batch_size`), in
    which the root find and `transition` run (`_end_lanes`; in most
    iterations a few lanes: one batch, and none without). With
    `loop.one_event_batch` (on a GPU: each pass of a loop costs a round trip
    to the host, and thousands of lanes end in every step) the batch is every
    lane, each one kept or replaced as it ends or not.
    """
    loop = loop_for("cpu") if loop is None else loop
    lanes = c.t.shape[0]
    a = jax.vmap(_attempt, in_axes=(0,) + in_axes + (None, None))(
        c, block, base, motion, duration, opts
    )
    # The lanes that move on, and those that do not (inactive lanes keep
    # their carry).
    new = where_lanes(a.moves_on, _moved(c, a, block, base, motion, in_axes), c)
    ends = is_active(c, opts) & ~a.moves_on
    # The lanes' motion is gathered as `in_axes` says (a record is not copied).
    lanes_a = eqx.tree_at(lambda a: a.args.motion, a, None, is_leaf=is_none)
    motion_axes = in_axes[2]
    end_lanes = functools.partial(_end_lanes, duration=duration, opts=opts)
    if loop.one_event_batch:
        ended = jax.lax.cond(
            jnp.any(ends),
            lambda: end_lanes(c, lanes_a, ends, motion, motion_axes),
            lambda: new,
        )
        return where_lanes(ends, ended, new), a
    batch = _batch_size(lanes, base)
    # The lanes that end, in order: the k-th is the first lane whose count of
    # ending lanes up to it is k + 1 (`lanes`, none, past the last).
    count = jnp.sum(ends)
    ranks = jnp.cumsum(ends)

    def end_batch(state):
        j, done = state
        wanted = j * batch + jnp.arange(batch)
        take = jnp.sum(ranks[None, :] <= wanted[:, None], axis=1)
        index = jnp.minimum(take, lanes - 1)
        sub, sub_c = jax.tree_util.tree_map(lambda x: x[index], (lanes_a, c))
        sub_motion = _take_lanes(motion, motion_axes, index)
        ended = end_lanes(sub_c, sub, take < lanes, sub_motion, motion_axes)
        done = jax.tree_util.tree_map(
            lambda d, x: jax.lax.dynamic_update_index_in_dim(d, x, j, 0), done, ended
        )
        return j + 1, done

    # The batches' carries, in order of the lanes that end, go back to their
    # lanes by a gather after the loop: a scatter would keep the step loop
    # from compiling as one kernel (`_xla.py`), and a gather inside the loop
    # would fuse the batch's computation into each of the lanes' reads.
    batches = -(-lanes // batch)
    done = jax.tree_util.tree_map(
        lambda x: jnp.zeros((batches, batch) + x.shape[1:], x.dtype), new
    )
    _, done = jax.lax.while_loop(
        lambda state: state[0] * batch < count, end_batch, (0, done)
    )
    back = jnp.maximum(ranks - 1, 0)
    done = jax.tree_util.tree_map(
        lambda d: d.reshape((batches * batch,) + d.shape[2:])[back], done
    )
    new = where_lanes(ends, done, new)
    return new, a
