"""One analysis: the segment loop of a hybrid (event-driven) rocking simulation.

Each segment is one Diffrax solve of the vector field in one phase (translation,
rising, falling) until an event (uplift, apex, impact, rising again, overturn,
a new peak of |u|) or the end of the window; the loop then applies the
transition (the impact map at an impact) and starts the next segment. The loop
is a `lax.while_loop`, so `simulate` runs under `jit` and `vmap`: a finished
lane performs zero-length solves until every lane is done.
"""

from enum import IntEnum

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ._block import Block
from ._dynamics import (
    Args,
    Phase,
    absolute_base_acceleration,
    impact,
    restitution,
    vector_field,
)
from ._events import (
    EVENT_ATOL,
    EVENT_RTOL,
    BracketedNewton,
    condition_a,
    condition_b,
    condition_base,
    condition_guard,
    condition_quiet,
    quiet,
)
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator, FixedBase, FrictionPendulum
from ._misc import (
    AbstractChecked,
    as_float,
    at_least_zero,
    first_true,
    greater_than_zero,
    is_count,
    parameter,
    positive,
)


class Outcome(IntEnum):
    """Outcome of one analysis (the colours of a behavior map)."""

    NO_ROCKING = 0
    ROCKING = 1
    OVERTURNED = 2


class Status(IntEnum):
    """How an analysis ended. Anything but SUCCESS means the numbers are not final."""

    SUCCESS = 0
    MAX_STEPS = 1  # a segment hit the solver's step limit (`max_steps`)
    MAX_SEGMENTS = 2  # the loop hit `max_segments` before the end of the window
    # The step-size controller or the event root finder failed, or an event was
    # missed (the block rotated past pi / 2 without overturning).
    SOLVER_FAILED = 3
    # A parameter out of its range inside compiled code (a module built from
    # traced values, which the checks at construction cannot see); every float
    # result is NaN.
    INVALID_INPUT = 4


class EventKind(IntEnum):
    """What ended a segment (reported in `History.event_kinds`)."""

    END = 0
    UPLIFT = 1
    APEX = 2
    IMPACT = 3  # impact followed by re-uplift about the other corner
    REST = 4  # impact after which rocking ends (pure translation)
    OVERTURN = 5
    REVERSAL = 6  # theta' changed sign before reaching theta = 0 (or the guard)
    BASE_PEAK = 7  # a new maximum of |u| (z in closed form: any reversal of u')
    FAILURE = 8
    QUIET = 9  # ground still and too little energy left to uplift or move further


class SolverOptions(AbstractChecked):
    """Numerical options. Tolerances are traced (new values do not recompile);
    the solver, `step` being set or not, and the limits are static.

    `rtol`, `atol`: PID tolerances. `solver`: a Diffrax solver (default Tsit5).
    `step`: a fixed step (s) instead of the PID controller; events are then
    located at step ends only (no root find), the naive baseline of the
    work-precision study. `max_steps`: step limit of one segment.
    `max_segments`: limit on the segments (events) of one analysis.
    `rest_tolerance`: the rest rule against Zeno chattering: rocking ends at an
    impact when the rebound could lift the block by less than
    `rest_tolerance * alpha`, estimated as theta'+^2 / (2 p^2 sin alpha) (free
    rocking from theta = 0), or when e <= 0 (Eq. 2.13).
    """

    rtol: Float[Array, ""] = parameter("rtol", default=1e-8)
    atol: Float[Array, ""] = parameter("atol", default=1e-10)
    max_steps: int = eqx.field(default=16384, static=True)
    max_segments: int = eqx.field(default=2000, static=True)
    rest_tolerance: Float[Array, ""] = parameter("rest_tolerance", default=1e-6)
    solver: diffrax.AbstractSolver = eqx.field(
        default_factory=diffrax.Tsit5, static=True
    )
    step: Float[Array, ""] | None = None

    def __check_init__(self):
        for name in ("max_steps", "max_segments"):
            value = getattr(self, name)
            if not is_count(value) or value < 1:
                raise ValueError(f"`{name}` must be an integer >= 1, got {value!r}")

    def constraints(self):
        out = [
            greater_than_zero("rtol", self.rtol),
            greater_than_zero("atol", self.atol),
            at_least_zero("rest_tolerance", self.rest_tolerance),
        ]
        if self.step is not None:
            out.append(greater_than_zero("step", self.step))
        return out


class History(eqx.Module):
    """Time histories of one analysis (SI units), sampled and at every event."""

    t: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    u: np.ndarray
    u_dot: np.ndarray
    z: np.ndarray
    regime: np.ndarray  # 0 translation, +1 / -1 rocking about x = +b / -b
    ground_acceleration: np.ndarray
    event_times: np.ndarray
    event_kinds: tuple[str, ...]
    alpha: float  # the block's alpha (rad), to plot theta / alpha


class Response(eqx.Module):
    """Result of `simulate` (and, with leading axes, of a behavior map).

    outcome: `Outcome` code. max_rotation: max |theta| / alpha (pi / (2 alpha)
    when overturned). max_base_displacement: max |u| (m), 0 on a fixed base.
    impacts: number of impacts. uplift_time: first uplift (s), NaN if none.
    status: `Status` code. steps, segments: solver steps and loop segments.
    history: `History` when asked for, else None.
    """

    outcome: Int[Array, "..."]
    max_rotation: Float[Array, "..."]
    max_base_displacement: Float[Array, "..."]
    impacts: Int[Array, "..."]
    uplift_time: Float[Array, "..."]
    status: Int[Array, "..."]
    steps: Int[Array, "..."]
    segments: Int[Array, "..."]
    history: History | None = None

    @property
    def ok(self):
        return self.status == Status.SUCCESS

    def summary(self) -> str:
        """One line: outcome, max rotation, max base displacement, impacts."""
        if int(self.status) == Status.INVALID_INPUT:
            return (
                "INVALID_INPUT: a parameter of the block, base, motion or options "
                "is out of its range (built from traced values, so not checked "
                "when built); the results are NaN"
            )
        outcome = Outcome(int(self.outcome)).name
        uplift = float(self.uplift_time)
        text = (
            f"{outcome}: max|theta|/alpha = {float(self.max_rotation):.6g}, "
            f"max|u| = {float(self.max_base_displacement):.6g} m, "
            f"impacts = {int(self.impacts)}, uplift at "
            + ("never" if np.isnan(uplift) else f"{uplift:.6g} s")
        )
        if int(self.status) != Status.SUCCESS:
            text += f" [status {Status(int(self.status)).name}: not converged]"
        return text


class _Carry(eqx.Module):
    t: Float[Array, ""]
    y: tuple
    phase: Int[Array, ""]
    sign: Float[Array, ""]
    max_theta: Float[Array, ""]
    max_u: Float[Array, ""]
    impacts: Int[Array, ""]
    uplift_time: Float[Array, ""]
    rocked: Bool[Array, ""]
    overturned: Bool[Array, ""]
    status: Int[Array, ""]
    segments: Int[Array, ""]
    steps: Int[Array, ""]
    segment_steps: Int[Array, ""]  # steps of the current segment so far
    done: Bool[Array, ""]
    kind: Int[Array, ""]
    dt: Float[Array, ""]  # next step (s): a segment's first, or the flat loop's next
    theta_ref: Float[Array, ""]  # s theta at the segment's start (for the guard)
    # A redo (see `_transition`) ends the segment's steps here (s); inf: no redo.
    t_limit: Float[Array, ""]


def _uplift_now(t, y, phase, block, base, motion):
    """In translation with |u'' + x_g''| >= g tan(alpha): rocking starts at once.

    Returns (uplift, sign). Applies at t = 0 and when rocking ends at an impact.
    """
    a_abs = absolute_base_acceleration(t, y[2], base, motion)
    threshold = block.uplift_acceleration
    uplift = (phase == Phase.TRANSLATION) & (jnp.abs(a_abs) >= threshold)
    return uplift, jnp.where(a_abs < 0, 1.0, -1.0)


def _initial_carry(block, base, motion, valid=True) -> _Carry:
    """At rest at t = 0; rocking at once if the ground's acceleration uplifts
    the block. With `valid` False (a parameter out of range) the analysis is
    over before it starts, with status INVALID_INPUT."""
    zero = jnp.zeros((), dtype=block.size.dtype)
    t = zero
    y = (zero, zero, base.initial_state())
    phase = jnp.asarray(Phase.TRANSLATION)
    uplift, sign = _uplift_now(t, y, phase, block, base, motion)
    valid = valid & block.valid() & base.valid() & motion.valid()
    uplift = uplift & valid
    return _Carry(
        t=t,
        y=y,
        phase=jnp.where(uplift, Phase.RISING, phase),
        sign=sign,
        max_theta=zero,
        max_u=zero,
        impacts=jnp.asarray(0),
        uplift_time=jnp.where(uplift, t, jnp.nan),
        rocked=uplift,
        overturned=jnp.asarray(False),
        status=jnp.where(valid, Status.SUCCESS, Status.INVALID_INPUT),
        segments=jnp.asarray(0),
        steps=jnp.asarray(0),
        segment_steps=jnp.asarray(0),
        done=~valid,
        kind=jnp.asarray(EventKind.END),
        dt=jnp.asarray(1e-3, dtype=zero.dtype),
        theta_ref=zero,
        t_limit=jnp.asarray(jnp.inf, dtype=zero.dtype),
    )


def _segment_end(c: _Carry, motion, duration):
    """(shaking, end of the segment): a segment stops at the end of the
    excitation (the step limit that keeps uplifts from hiding inside a step is
    needed only while the ground moves), else at `duration`."""
    shaking = c.t < motion.end_time
    return shaking, jnp.where(shaking, jnp.minimum(motion.end_time, duration), duration)


def _setup_conditions(base):
    """The event conditions, in order: the first that fires ends the segment."""
    conditions = (condition_a, condition_b, condition_guard)
    if not isinstance(base, FixedBase):
        peak = base.peak_condition() or condition_base
        conditions = conditions + (peak, condition_quiet)
    return conditions


def _setup(c: _Carry, block, base, motion, duration, opts):
    """What a segment (or a step of the flat loop) starts from: whether the lane
    is active, the vector field's arguments, the event conditions, the end of
    the segment, the largest step (None: no limit) and the step-size controller."""
    active = ~c.done & (c.segments < opts.max_segments)
    args = Args(
        block,
        base,
        motion,
        c.phase,
        c.sign,
        c.max_u,
        c.t >= motion.end_time,
        c.theta_ref,
    )
    conditions = _setup_conditions(base)
    shaking, t_stop = _segment_end(c, motion, duration)
    t_stop = jnp.minimum(t_stop, c.t_limit)
    max_step = motion.max_step
    dtmax = None if max_step is None else jnp.where(shaking, max_step, jnp.inf)
    controller = diffrax.PIDController(
        rtol=opts.rtol,
        atol=opts.atol,
        dtmax=dtmax,
        step_ts=motion.step_ts,
        jump_ts=motion.jump_ts,
    )
    return active, args, conditions, t_stop, dtmax, controller


def _solve_segment(c: _Carry, block, base, motion, duration, opts, dense=False):
    """Integrate from c.t to the next event (or `duration`): a Diffrax solution."""
    active, args, conditions, t_stop, _, controller = _setup(
        c, block, base, motion, duration, opts
    )
    if opts.step is None:
        # The first step is the previous segment's mean step (no step-size
        # selection, which costs two evaluations a segment).
        root_finder, dt0 = BracketedNewton(rtol=EVENT_RTOL, atol=EVENT_ATOL), c.dt
    else:
        controller, root_finder, dt0 = diffrax.ConstantStepSize(), None, opts.step
    event = diffrax.Event(conditions, root_finder=root_finder, direction=False)
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


# A redo ends at least this long (s) before the event it replaces.
REDO_MARGIN = 1e-9


def redo_limit(t0, t, candidates, start_values, event_values):
    """Where a redo ends (inf: none) when conditions among `candidates` (all
    but the one that fired) went from > 0 at t0 to < 0 at the event t: their
    roots came first.

    Half-way from the earliest of their roots (secant estimates) to t: the redo
    integrates its last step differently, and a root close to t could move
    before a limit just short of it (a slow impact moved by 3e-8 s); if an
    estimate is late, the redo ends without the earlier root, and the next
    segment repeats this from closer.
    """
    limit = jnp.asarray(jnp.inf, dtype=t.dtype)
    for candidate, v0, v1 in zip(candidates, start_values, event_values):
        earlier = candidate & (v0 > 0) & (v1 < 0)
        root = t0 + (t - t0) * v0 / jnp.where(earlier, v0 - v1, 1.0)
        limit = jnp.where(earlier, jnp.minimum(limit, 0.5 * (root + t)), limit)
    return jnp.where(jnp.isinf(limit), limit, jnp.minimum(limit, t - REDO_MARGIN))


def _transition(
    c: _Carry, sol, block, base, motion, duration, opts, limit=None
) -> _Carry:
    """Apply what ended the segment: uplift, apex, impact map, overturn, ...

    An event that is not the earliest root in its step (where several fire,
    Diffrax takes the first in order) is not applied: the segment is redone
    from its start up to `limit` (`redo_limit`, computed here from the
    conditions at the segment's start unless given), where the earlier root
    fires alone. No redo inside a redo, nor within 2 `REDO_MARGIN` of the
    segment's start: roots closer than that end as one event (the first in
    order).
    """
    active = ~c.done & (c.segments < opts.max_segments)
    t = sol.ts[-1]
    theta, theta_dot, base_state = jax.tree_util.tree_map(lambda x: x[-1], sol.ys)
    event = sol.result == diffrax.RESULTS.event_occurred
    if limit is None:
        _, args, conditions, *_ = _setup(c, block, base, motion, duration, opts)
        y_event = (theta, theta_dot, base_state)
        limit = redo_limit(
            c.t,
            t,
            [~m for m in sol.event_mask],
            [cond(c.t, c.y, args) for cond in conditions],
            [cond(t, y_event, args) for cond in conditions],
        )
    redo = active & event & jnp.isfinite(limit) & jnp.isinf(c.t_limit)
    redo = redo & (t - 2.0 * REDO_MARGIN > c.t)
    reached_end = sol.result == diffrax.RESULTS.successful
    # A step that ends before the segment's end (the flat loop of maps) only
    # moves the state on.
    cut = reached_end & (t < _segment_end(c, motion, duration)[1])
    segment_steps = c.segment_steps + sol.stats["num_steps"]
    too_long = segment_steps > opts.max_steps
    failed = active & (~(event | reached_end) | too_long)
    reached_end = reached_end & ~cut
    mask = [m & event for m in sol.event_mask]
    hit_a, hit_b, hit_guard = mask[0], mask[1], mask[2]
    hit_base = mask[3] if len(mask) > 3 else jnp.asarray(False)
    hit_quiet = mask[4] if len(mask) > 4 else jnp.asarray(False)
    phase, sign = c.phase, c.sign

    uplift = (phase == Phase.TRANSLATION) & (hit_a | hit_b)
    overturn = (phase == Phase.RISING) & hit_a
    apex = (phase == Phase.RISING) & hit_b
    # An apex at or below theta = 0 (a rebound too small to lift the block, as
    # at the end of a Zeno sequence of impacts with `rest_tolerance` 0): the
    # block rests on its base. (Falling from there, the impact condition
    # s theta would start <= 0 and never fire.)
    grounded = apex & (sign * theta <= 0)
    apex = apex & ~grounded
    hit_ground = (phase == Phase.FALLING) & hit_a
    reversal = (phase == Phase.FALLING) & hit_b
    # Guard (a phase begun on the wrong side of a near double root): rising
    # after all, falling after all, or, right after uplift, never really lifted.
    guard_up = (phase == Phase.FALLING) & hit_guard
    guard_down = (phase == Phase.RISING) & hit_guard & (c.theta_ref > 0)
    settled = ((phase == Phase.RISING) & hit_guard & (c.theta_ref <= 0)) | grounded

    # Impact map with the rest rule.
    e, _ = restitution(block, base)
    rise = (e * theta_dot) ** 2 / (2.0 * block.p**2 * block.b / block.size)
    rest = (e <= 0) | (rise < opts.rest_tolerance * block.alpha)
    post_theta_dot, post_base = impact(block, base, theta_dot, base_state, rest)
    theta_dot = jnp.where(hit_ground, post_theta_dot, theta_dot)
    if base_state is not None:
        base_state = jnp.where(hit_ground, post_base, base_state)
        base_state = base.at_transition(base_state, hit_base)
    theta = jnp.where(hit_ground | uplift | settled, 0.0, theta)
    theta_dot = jnp.where(settled, 0.0, theta_dot)

    new_phase = first_true(
        [
            uplift,
            apex,
            hit_ground & ~rest,
            hit_ground & rest,
            reversal | guard_up,
            guard_down,
            settled,
        ],
        [
            Phase.RISING,
            Phase.FALLING,
            Phase.RISING,
            Phase.TRANSLATION,
            Phase.RISING,
            Phase.FALLING,
            Phase.TRANSLATION,
        ],
        phase,
    )
    new_sign = jnp.where(uplift, jnp.where(hit_a, 1.0, -1.0), sign)
    new_sign = jnp.where(hit_ground & ~rest, -sign, new_sign)
    y = (theta, theta_dot, base_state)
    again, again_sign = _uplift_now(t, y, new_phase, block, base, motion)
    again = again & hit_ground & rest
    new_phase = jnp.where(again, Phase.RISING, new_phase)
    new_sign = jnp.where(again, again_sign, new_sign)
    started = uplift | again

    max_theta = jnp.maximum(c.max_theta, jnp.abs(theta))
    # max |u| over segment ends (its peaks are located events), as `simulate`
    # sees it: the flat loop's steps that only move the state on ("cut") do not
    # raise it, else the "base" condition (|u| above it) would be <= 0 only
    # near the top of a peak, and a step over that top would miss the peak.
    max_u = (
        c.max_u
        if base_state is None
        else jnp.where(cut, c.max_u, jnp.maximum(c.max_u, jnp.abs(base_state[0])))
    )
    # Nothing can happen any more (ground still, block in translation, base energy
    # too low): the analysis ends early.
    still = hit_quiet | (
        quiet(
            y,
            Args(
                block,
                base,
                motion,
                new_phase,
                new_sign,
                max_u,
                t >= motion.end_time,
                c.theta_ref,
            ),
        )
        <= 0
    )
    max_theta = jnp.where(overturn, 0.5 * jnp.pi, max_theta)
    status = jnp.where(
        failed,
        jnp.where(
            (sol.result == diffrax.RESULTS.max_steps_reached) | too_long,
            Status.MAX_STEPS,
            Status.SOLVER_FAILED,
        ),
        c.status,
    )
    kind = first_true(
        [
            failed,
            uplift,
            apex,
            hit_ground & ~rest,
            hit_ground & rest,
            overturn,
            reversal | guard_up | guard_down,
            settled,
            hit_base,
            still,
        ],
        [
            EventKind.FAILURE,
            EventKind.UPLIFT,
            EventKind.APEX,
            EventKind.IMPACT,
            EventKind.REST,
            EventKind.OVERTURN,
            EventKind.REVERSAL,
            EventKind.REST,
            EventKind.BASE_PEAK,
            EventKind.QUIET,
        ],
        EventKind.END,
    )
    new = _Carry(
        t=t,
        y=y,
        phase=new_phase,
        sign=new_sign,
        max_theta=max_theta,
        max_u=max_u,
        impacts=c.impacts + hit_ground.astype(c.impacts.dtype),
        uplift_time=jnp.where(jnp.isnan(c.uplift_time) & started, t, c.uplift_time),
        rocked=c.rocked | started,
        overturned=c.overturned | overturn,
        status=status,
        segments=c.segments + jnp.where(cut, 0, 1),
        steps=c.steps + sol.stats["num_steps"],
        segment_steps=jnp.where(cut, segment_steps, 0),
        done=overturn | failed | (reached_end & ~event & (t >= duration)) | still,
        theta_ref=jnp.where(cut, c.theta_ref, new_sign * theta),
        dt=jnp.where(
            sol.stats["num_steps"] > 0,
            (t - c.t) / jnp.maximum(sol.stats["num_steps"], 1),
            c.dt,
        ),
        kind=kind,
        t_limit=jnp.where(event | (t >= c.t_limit), jnp.inf, c.t_limit),
    )
    # A frozen lane keeps its carry; a redo too, but for its limit and steps.
    redone = eqx.tree_at(
        lambda c: (c.t_limit, c.steps, c.kind),
        c,
        (
            jnp.where(redo, limit, c.t_limit),
            jnp.where(redo, new.steps, c.steps),
            jnp.where(redo, EventKind.END, c.kind),
        ),
    )
    return jax.tree_util.tree_map(
        lambda n, r: jnp.where(active & ~redo, n, r), new, redone
    )


def _response(c: _Carry, block, opts) -> Response:
    status = jnp.where(c.done, c.status, Status.MAX_SEGMENTS)
    status = jnp.where(c.status != Status.SUCCESS, c.status, status)
    # |theta| beyond pi / 2 without the overturn event: an event was missed,
    # and nothing after it can be trusted.
    lost = ~c.overturned & (c.max_theta > 0.5 * jnp.pi)
    status = jnp.where(lost & (status == Status.SUCCESS), Status.SOLVER_FAILED, status)
    outcome = jnp.where(
        c.overturned,
        Outcome.OVERTURNED,
        jnp.where(c.rocked, Outcome.ROCKING, Outcome.NO_ROCKING),
    )
    invalid = status == Status.INVALID_INPUT
    nan = jnp.asarray(jnp.nan, dtype=c.max_theta.dtype)
    return Response(
        outcome=outcome,
        max_rotation=jnp.where(invalid, nan, c.max_theta / block.alpha),
        max_base_displacement=jnp.where(invalid, nan, c.max_u),
        impacts=c.impacts,
        uplift_time=jnp.where(invalid, nan, c.uplift_time),
        status=status,
        steps=c.steps,
        segments=c.segments,
    )


def run(block, base, motion, duration, opts: SolverOptions) -> Response:
    """The whole analysis as one traceable function (for `jit`, `vmap`, `jacfwd`)."""

    def cond(c):
        return ~c.done & (c.segments < opts.max_segments)

    def body(c):
        sol = _solve_segment(c, block, base, motion, duration, opts)
        return _transition(c, sol, block, base, motion, duration, opts)

    valid = opts.valid() & jnp.isfinite(duration) & (duration > 0)
    carry = jax.lax.while_loop(cond, body, _initial_carry(block, base, motion, valid))
    return _response(carry, block, opts)


_run_jit = eqx.filter_jit(run)


@eqx.filter_jit
def _segment_dense(c, block, base, motion, duration, opts):
    """One segment with its dense output, and the carry after its transition."""
    sol = _solve_segment(c, block, base, motion, duration, opts, dense=True)
    return _transition(c, sol, block, base, motion, duration, opts), sol


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
    grid = np.linspace(0.0, duration, int(round(duration / step)) + 1)
    c = _initial_carry(block, base, motion)

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
    if isinstance(base, FrictionPendulum):
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
    rtol: float = 1e-8,
    atol: float = 1e-10,
    history: bool = False,
    history_step: float | None = None,
    max_steps: int = 16384,
    max_segments: int = 2000,
    rest_tolerance: float = 1e-6,
    solver: diffrax.AbstractSolver | None = None,
) -> Response:
    """Simulate one block on a base under a ground motion (SI units, float64).

    Works under `jax.jit`, `jax.vmap` and `jax.jacfwd` (with `history=False`);
    physical parameters and `duration` are traced, so new values do not
    recompile.

    Args:
        block: the rigid block.
        base: `FixedBase()`, `LinearIsolator(...)` or `FrictionPendulum(...)`.
        motion: an `MPPulse`, a `SinePulse` or a `Record`.
        duration: length of the analysis (s); default: the end of the
            excitation plus 5 s.
        rtol, atol: the integrator's tolerances. Events are located to about
            1e-12 s on the dense output whatever they are.
        history: also return the time histories (`Response.history`), computed
            by a Python loop of compiled segments.
        history_step: spacing of the history's samples (s); every event is
            recorded as well. Default: duration / 2000, at most 0.01 s.
        max_steps: the solver's step limit in one segment.
        max_segments: the limit on segments (events) of the analysis.
        rest_tolerance: the rest rule (`SolverOptions`).
        solver: a Diffrax solver; default `diffrax.Tsit5()`.

    Returns:
        A `Response`. Check `response.status` (or `response.ok`): anything but
        `Status.SUCCESS` means the numbers are not final.

    Example:
        >>> import jaxrock as jr
        >>> r = jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(),
        ...                 jr.near_fault_pulse("Northridge JFA/SN"))
        >>> r.ok
        Array(True, dtype=bool)
    """
    _check_single(block, base, motion)
    if duration is None:
        duration = motion.end_time + 5.0
    positive("duration", duration)
    duration = as_float(duration)
    opts = SolverOptions(
        rtol, atol, max_steps, max_segments, rest_tolerance, solver or diffrax.Tsit5()
    )
    if not history:
        return _run_jit(block, base, motion, duration, opts)
    if history_step is None:
        history_step = min(float(duration) / 2000.0, 0.01)
    positive("history_step", history_step)
    c, hist = _history(block, base, motion, duration, opts, history_step)
    response = _response(c, block, opts)
    return eqx.tree_at(lambda r: r.history, response, hist, is_leaf=lambda x: x is None)


def check_base_and_motion(base, motion):
    """`ValueError` unless `base` is an isolator and `motion` a ground motion."""
    if not isinstance(base, AbstractIsolator):
        raise ValueError(
            "`base` must be FixedBase, LinearIsolator or FrictionPendulum, got "
            f"{type(base).__name__}"
        )
    if not isinstance(motion, AbstractGroundMotion):
        raise ValueError(
            "`motion` must be an MPPulse, SinePulse or Record, got "
            f"{type(motion).__name__}"
        )


def _check_single(block, base, motion):
    """`simulate`'s inputs: one block, one base, one motion (batches of
    concrete values go to `behavior_map`, or `jax.vmap` over `simulate`)."""
    if not isinstance(block, Block):
        raise ValueError(f"`block` must be a jaxrock.Block, got {type(block).__name__}")
    check_base_and_motion(base, motion)
    for name, module in (("block", block), ("base", base), ("motion", motion)):
        shapes = {
            np.shape(x)
            for x in jax.tree_util.tree_leaves(module)
            if not (name == "motion" and x is getattr(module, "samples", None))
        }
        if shapes - {()}:
            raise ValueError(
                f"`{name}` must hold one value per parameter in `simulate`, got "
                f"shapes {sorted(shapes)}: use `behavior_map` for batches, or "
                "`jax.vmap(simulate)`"
            )
