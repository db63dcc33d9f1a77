"""The event-driven model that both engines share: the carry of one analysis,
its start, the event conditions of a segment, the transition at an event and
the response at the end.

jaxrock has two engines. `simulate` (`_simulate.py`) runs one Diffrax solve
per event-to-event segment in a `lax.while_loop`: it carries forward-mode
gradients and records time histories. Behavior maps (`_flat.py`, `_maps.py`)
run a flat loop in which every iteration advances each of many vmapped lanes
by one solver step, so lanes never wait for each other's segments. Both apply
the same vector field (`_dynamics.py`), the same conditions (`_events.py`)
and the same `transition` below, and the tests check that a map equals
`simulate` cell by cell.
"""

from collections.abc import Callable
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from ._controller import KinkClip, StepSizeController
from ._dynamics import (
    Args,
    Phase,
    absolute_base_acceleration,
    base_acceleration_bound,
    impact,
    impact_friction,
    in_stop,
    rest_level,
    restitution,
    restitution_valid,
    rests_at_impact,
    uplift_level,
)
from ._events import (
    checks_friction,
    condition_angle,
    condition_base,
    condition_flight,
    condition_guard,
    condition_quiet,
    condition_rate,
    condition_slide,
    condition_stop,
    corner_margin,
    never_uplifts,
    quiet,
    slide_margin,
)
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator, check_declared_shapes
from ._misc import GRAVITY, first_true, is_none
from ._results import DECISION_WINDOW, EventKind, Outcome, Response, Status
from ._scene import (
    carries_conditions,
    carries_quiet_end,
    fixed_base,
    has_vertical,
    rest_jumps,
)
from ._trig import sincos


class Carry(eqx.Module):
    """The state of one analysis between segments (SI units): the time and
    state y = (theta, theta', base state), the phase and rocking sign, the
    running maxima of |theta| and |u|, counts, the first uplift, how it ended
    so far (`status`, `done`, the last event's `kind`), the next step `dt`,
    s theta where the phase began (`theta_ref`, for the guard) and the end of
    a redo (`t_limit`, inf: none)."""

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
    # A redo (see `transition`) ends the segment's steps here (s); inf: no redo.
    t_limit: Float[Array, ""]
    # On a base with a hysteretic state (costly conditions: a friction
    # pendulum's z), the event conditions' values at (t, y) (`start_conditions`),
    # else None. Only the flat loop of maps reads them, as the next step's
    # values at its start, and keeps them current; `simulate` leaves them as
    # `initial_carry` set them.
    start_conditions: tuple | None = None
    # Where the scene `carries_quiet_end` (a block on a fixed base under a
    # record with its table of peaks), else None: the sample where |x_g''|
    # may first reach the block's uplift level, found from an earlier time
    # (`RecordSignal.quiet_end`). Only the flat loop of maps reads it (while
    # `quiet_holds`), and keeps it current in its event batches
    # (`_flat._end_lanes`); `simulate` searches at every step.
    quiet_end: Float[Array, ""] | None = None
    # Where the scene has `rest_jumps`, else None: the first sample at which
    # a lane at rest searches for a jump (`_flat._rest_jump`).
    search_from: Float[Array, ""] | None = None
    # Of a block with a `friction`, else None: the friction needed to hold it
    # exceeded its own at some time (`condition_slide`, `impact_friction`).
    slid: Bool[Array, ""] | None = None


def _uplift_now(t, y, phase, block, base, motion):
    """In translation with |u'' + x_g''| >= g tan(alpha): rocking starts at once.

    Returns (uplift, sign). Applies at t = 0 and at the end of every
    segment: where the block comes to rest (at an impact, or settling back
    with an apex at or below theta = 0 as the ground swings to lift it on
    its other corner) or the base meets its stop (whose dashpot's force
    jumps), the uplift conditions would start the next segment at <= 0 and
    never fire.
    """
    a_abs = absolute_base_acceleration(t, y[2], base, motion, in_stop(y[2], base))
    threshold = uplift_level(block, motion.gravity(t))
    uplift = (phase == Phase.TRANSLATION) & (jnp.abs(a_abs) >= threshold)
    return uplift, jnp.where(a_abs < 0, 1.0, -1.0)


def initial_carry(block, base, motion, valid=True) -> Carry:
    """At rest at t = 0; rocking at once if the ground's acceleration uplifts
    the block. With `valid` False (a parameter out of range) the analysis is
    over before it starts, with status INVALID_INPUT."""
    zero = jnp.zeros((), dtype=block.size.dtype)
    t = zero
    y = (zero, zero, base.initial_state())
    phase = jnp.asarray(Phase.TRANSLATION)
    uplift, sign = _uplift_now(t, y, phase, block, base, motion)
    valid = valid & block.valid() & base.valid() & motion.valid()
    valid = valid & restitution_valid(block, base)
    uplift = uplift & valid
    c = Carry(
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
        quiet_end=quiet_end(t, block, base, motion, None),
        search_from=zero if rest_jumps(motion) else None,
        slid=None if block.friction is None else jnp.asarray(False),
    )
    if c.slid is not None:
        slid = slides_now(c, block, base, motion) & valid
        c = eqx.tree_at(lambda c: c.slid, c, slid)
    if has_vertical(motion):  # the ground falls faster than g at once
        flight = valid & (motion.gravity(t) <= 0)
        c = eqx.tree_at(
            lambda c: (c.done, c.status),
            c,
            (c.done | flight, jnp.where(flight, Status.FREE_FLIGHT, c.status)),
        )
    return with_start_conditions(c, block, base, motion)


def slides_now(c: Carry, block, base, motion):
    """Whether the block has slid by the carry's time, in its phase: it had,
    or friction cannot hold it there (`condition_slide` <= 0: a condition
    that starts a segment at <= 0 never fires). None without a `friction`."""
    if c.slid is None:
        return None
    args = segment_args(c, block, base, motion)
    return c.slid | (condition_slide(c.t, c.y, args) <= 0)


def is_active(c: Carry, opts):
    """The analysis goes on: not done, and within `opts.max_segments`."""
    return ~c.done & (c.segments < opts.max_segments)


def lane_window(motion, duration, opts):
    """The end of a lane's analysis (s): `duration`, or where it runs until
    decided (`SolverOptions.until_decided`), `DECISION_WINDOW` after the end
    of the lane's own motion. A batch's or a suite's `duration` ends that
    long after its longest motion: each cell then ends as under its motion
    alone."""
    own = motion.end_time + DECISION_WINDOW
    return jnp.where(opts.until_decided, jnp.minimum(duration, own), duration)


def segment_end(c: Carry, motion, duration, opts):
    """(shaking, end of the segment): a segment stops at the end of the
    excitation (the step limit that keeps uplifts from hiding inside a step is
    needed only while the ground moves), else at the lane's window's end
    (`lane_window`)."""
    end = lane_window(motion, duration, opts)
    shaking = c.t < motion.end_time
    return shaking, jnp.where(shaking, jnp.minimum(motion.end_time, end), end)


def segment_setup(c: Carry, block, base, motion, duration, opts):
    """What a segment (or a step of the flat loop) starts from: whether the lane
    is active, the vector field's arguments, the event conditions, the end of
    the segment, the largest step (None: no limit) and the step-size controller."""
    active = is_active(c, opts)
    args = segment_args(c, block, base, motion)
    conditions = event_conditions(block, base, motion)
    shaking, t_stop = segment_end(c, motion, duration, opts)
    t_stop = jnp.minimum(t_stop, c.t_limit)
    quiet_below = quiet_level(c, block, base, motion)
    kinks = motion.limits_steps(quiet_below is not None)
    max_step = motion.max_step
    dtmax = None
    if max_step is not None:
        limited = shaking
        if kinks and quiet_below is not None:
            # A block at rest whose steps end before |x_g''| could reach its
            # level (`next_kink`) needs no step limit: that bound keeps its
            # uplift from hiding inside a step.
            limited = shaking & ~(quiet_below > 0)
        dtmax = jnp.where(limited, max_step, jnp.inf)
    controller = StepSizeController(rtol=opts.rtol, atol=opts.atol, dtmax=dtmax)
    if kinks:
        at_g = quiet_level(c, block, base, motion, at_g=True)
        controller = KinkClip(controller, motion, at_g)
    return active, args, conditions, t_stop, dtmax, controller


def segment_args(c: Carry, block, base, motion, t=None) -> Args:
    """What the vector field and the conditions of the carry's segment read
    (at t, by default the carry's)."""
    t = c.t if t is None else t
    ended = t >= motion.end_time
    args = (c.phase, c.sign, c.max_u, ended, c.theta_ref, c.slid)
    if fixed_base(base):
        return Args(block, base, motion, *args)
    step_bound = jnp.where(ended, jnp.inf, motion.step_bound)
    peak_time = jnp.where(c.kind == EventKind.BASE_PEAK, c.t, jnp.nan)
    pushed = in_stop(c.y[2], base)
    # Armed where the base moves out at the segment's start: a located
    # root of `stop_passage` (moving in) does not begin an armed segment.
    u, u_dot = c.y[2][0], c.y[2][1]
    armed = None if pushed is None else ~pushed & (jnp.sign(u) * u_dot > 0)
    return Args(block, base, motion, *args, pushed, step_bound, peak_time, armed)


def with_start_conditions(c: Carry, block, base, motion) -> Carry:
    """The carry with its `start_conditions`: each event condition (in the
    order of `event_conditions`) at (c.t, c.y), on a base with a hysteretic
    state; unchanged (None) on others."""
    if not carries_conditions(base):
        return c
    args = segment_args(c, block, base, motion)
    conditions = jax.tree_util.tree_leaves(event_conditions(block, base, motion))
    values = tuple(cond(c.t, c.y, args) for cond in conditions)
    return eqx.tree_at(lambda c: c.start_conditions, c, values, is_leaf=is_none)


def quiet_level(c: Carry, block, base, motion, at_g: bool = False):
    """|x_g''| below which nothing happens from c.t on: a block at rest on a
    fixed base uplifts (or slides) only where |x_g''| reaches its
    `rest_level` at the least g_eff from c.t on (`least_gravity_from`;
    `at_g`: at g, for `KinkClip` to lower step by step, `level_from`); 0
    while it rocks; None on an isolated base (its state moves)."""
    if not fixed_base(base):
        return None
    gravity = GRAVITY if at_g else motion.least_gravity_from(c.t)
    return jnp.where(
        c.phase == Phase.TRANSLATION, rest_level(block, c.slid, gravity), 0.0
    )


def quiet_end(t, block, base, motion, slid):
    """`Carry.quiet_end` from t: where |x_g''| may first reach the block's
    `rest_level` from t on (`RecordSignal.quiet_end`; `slid`: whether it has
    slid, None without a friction), where the scene
    `carries_quiet_end`; else None."""
    if not carries_quiet_end(base, motion):
        return None
    return motion.quiet_end(t, rest_level(block, slid, motion.least_gravity_from(t)))


# A redo ends at least this long (s) before the event it replaces.
REDO_MARGIN = 1e-9


def redo_limit(t0, t, candidates, start_values, event_values):
    """Where a redo ends (inf: none) when conditions among `candidates` (all
    but the one that fired) are < 0 at the event t: their roots came first.

    Half-way from the earliest of their roots (secant estimates from t0) to
    t: the redo integrates its last step differently, and a root close to t
    could move before a limit just short of it (a slow impact moved by 3e-8
    s); if an estimate is late, the redo ends without the earlier root, and
    the next segment repeats this from closer. A condition <= 0 at t0 is on
    its boundary there (an event of its own, e.g. a base peak, began the
    segment): it rose and crossed again before t, and its root is taken at
    t0 (the redo ends half-way).
    """
    limit = jnp.asarray(jnp.inf, dtype=t.dtype)
    for candidate, v0, v1 in zip(candidates, start_values, event_values):
        earlier = candidate & (v1 < 0)
        rose = v0 > 0
        root = t0 + (t - t0) * jnp.where(rose, v0, 0.0) / jnp.where(
            earlier & rose, v0 - v1, 1.0
        )
        limit = jnp.where(earlier, jnp.minimum(limit, 0.5 * (root + t)), limit)
    return jnp.where(jnp.isinf(limit), limit, jnp.minimum(limit, t - REDO_MARGIN))


class Conditions(NamedTuple):
    """The event conditions of a segment, as Diffrax's `Event` takes them (a
    PyTree; its `event_mask` has the same structure). Each is > 0 inside its
    phase and fires where it reaches 0 (`_events.py` tabulates them by phase).
    When several fire in one step Diffrax takes the first in this order;
    `transition` then redoes the segment if another's root came earlier."""

    angle: Callable  # uplift towards +b; overturn (rising); impact (falling)
    rate: Callable  # uplift towards -b; apex (rising); rising again (falling)
    guard: Callable  # a rocking phase begun on the wrong side of a double root
    base_peak: Callable | None = None  # a new peak of |u| (isolated bases)
    quiet: Callable | None = None  # nothing can happen any more (isolated bases)
    slide: Callable | None = None  # friction cannot hold the block (a `friction`)
    flight: Callable | None = None  # g_eff reaches 0 (vertical ground motion)
    stop: Callable | None = None  # the base meets or leaves its stop


def event_conditions(block, base, motion) -> Conditions:
    """The conditions of a segment of `block` on `base` under `motion` (a
    fixed base has no base state, a block without a `friction` no check of
    sliding, a motion without a vertical part no free flight)."""
    slide = None if block.friction is None else condition_slide
    flight = condition_flight if has_vertical(motion) else None
    stop = None if base.stop is None else condition_stop
    if fixed_base(base):
        return Conditions(
            condition_angle,
            condition_rate,
            condition_guard,
            slide=slide,
            flight=flight,
        )
    peak = base.peak_condition() or condition_base
    return Conditions(
        condition_angle,
        condition_rate,
        condition_guard,
        peak,
        condition_quiet,
        slide,
        flight,
        stop,
    )


class _SegmentEnd(NamedTuple):
    """How a segment (or one step of the flat loop) ended."""

    t: Array
    y: tuple
    event: Array  # an event condition fired
    reached_end: Array  # the segment's end (the window's, or the excitation's)
    cut: Array  # a flat-loop step that ends before the segment's end
    failed: Array
    status: Array  # the status after it
    segment_steps: Array  # steps of the segment so far


def _classify_end(c: Carry, sol, motion, duration, opts, active) -> _SegmentEnd:
    t = sol.ts[-1]
    y = jax.tree_util.tree_map(lambda x: x[-1], sol.ys)
    event = sol.result == diffrax.RESULTS.event_occurred
    reached_end = sol.result == diffrax.RESULTS.successful
    # A step that ends before the segment's end (the flat loop of maps) only
    # moves the state on.
    cut = reached_end & (t < segment_end(c, motion, duration, opts)[1])
    segment_steps = c.segment_steps + sol.stats["num_steps"]
    too_long = segment_steps > opts.max_steps
    failed = active & (~(event | reached_end) | too_long)
    status = jnp.where(
        failed,
        jnp.where(
            (sol.result == diffrax.RESULTS.max_steps_reached) | too_long,
            Status.MAX_STEPS,
            Status.SOLVER_FAILED,
        ),
        c.status,
    )
    return _SegmentEnd(
        t, y, event, reached_end & ~cut, cut, failed, status, segment_steps
    )


class _Events(NamedTuple):
    """What the fired conditions mean in the segment's phase (`_decode`)."""

    uplift: Array  # "angle" or "rate" in translation
    overturn: Array  # "angle" while rising
    apex: Array  # "rate" while rising, above theta = 0
    impact: Array  # "angle" while falling (`rebound` or `rest`: the rest rule)
    reversal: Array  # "rate" while falling: rising again before the impact
    guard_up: Array  # "guard" while falling: it rises after all
    guard_down: Array  # "guard" while rising from theta_ref > 0: it falls
    settled: Array  # never really lifted (or an apex at theta = 0): at rest
    base_peak: Array  # "base_peak" (isolated bases)
    quiet: Array  # "quiet" (isolated bases)
    slide: Array  # "slide" where friction cannot hold the block
    corner: Array  # "slide" where it passes its corner's vertical first
    flight: Array  # "flight" (vertical ground motion)
    stop: Array  # "stop" (isolators with a stop)
    towards_plus: Array  # an uplift is about the corner at x = +b


class _Rule(NamedTuple):
    """An event, the phase after it (None: the phase goes on) and its kind."""

    event: str
    phase: Phase | None
    kind: EventKind


# The event table: what each event leads to, read by `_next_phase` and
# `_event_kind` (the first event that holds applies; the events of one
# segment exclude each other but for an impact, split here by the rest rule).
EVENT_TABLE = (
    _Rule("uplift", Phase.RISING, EventKind.UPLIFT),
    _Rule("apex", Phase.FALLING, EventKind.APEX),
    _Rule("rebound", Phase.RISING, EventKind.IMPACT),  # an impact, then rocking
    _Rule("rest", Phase.TRANSLATION, EventKind.REST),  # an impact that ends it
    _Rule("overturn", None, EventKind.OVERTURN),  # (the analysis ends)
    _Rule("reversal", Phase.RISING, EventKind.REVERSAL),
    _Rule("guard_up", Phase.RISING, EventKind.REVERSAL),
    _Rule("guard_down", Phase.FALLING, EventKind.REVERSAL),
    _Rule("settled", Phase.TRANSLATION, EventKind.REST),
    _Rule("base_peak", None, EventKind.BASE_PEAK),
    _Rule("slide", None, EventKind.SLIDE),
    _Rule("corner", None, EventKind.CORNER),
    _Rule("flight", None, EventKind.FLIGHT),  # (the analysis ends)
    _Rule("stop", None, EventKind.STOP),
)


def _holds(ev: _Events, rest) -> dict:
    """Each event of `EVENT_TABLE`: whether it holds."""
    return ev._asdict() | dict(rebound=ev.impact & ~rest, rest=ev.impact & rest)


def _decode(c: Carry, mask: Conditions, event, theta, slides=None) -> _Events:
    """The events of a segment that ended at `theta` (rad), from the fired
    conditions `mask`; `slides` (a block with a `friction`): whether a fired
    "slide" is one (its `slide_margin` below its `corner_margin`), else
    the block's passing its corner."""

    def hit(m):
        return jnp.asarray(False) if m is None else m & event

    angle, rate, guard = hit(mask.angle), hit(mask.rate), hit(mask.guard)
    translating = c.phase == Phase.TRANSLATION
    rising, falling = c.phase == Phase.RISING, c.phase == Phase.FALLING
    apex = rising & rate
    # An apex at or below theta = 0 (a rebound too small to lift the block, as
    # at the end of a Zeno sequence of impacts with `rest_tolerance` 0): the
    # block rests on its base. (Falling from there, the impact condition
    # s theta would start <= 0 and never fire.)
    grounded = apex & (c.sign * theta <= 0)
    return _Events(
        uplift=translating & (angle | rate),
        overturn=rising & angle,
        apex=apex & ~grounded,
        impact=falling & angle,
        reversal=falling & rate,
        guard_up=falling & guard,
        guard_down=rising & guard & (c.theta_ref > 0),
        settled=(rising & guard & (c.theta_ref <= 0)) | grounded,
        base_peak=hit(mask.base_peak),
        quiet=hit(mask.quiet),
        slide=hit(mask.slide) & (slides is None or slides),
        corner=hit(mask.slide) & (slides is not None and ~slides),
        flight=hit(mask.flight),
        stop=hit(mask.stop),
        towards_plus=angle,
    )


def _apply_jumps(ev: _Events, t, y, block, base, motion, opts):
    """The impact map (with the rest rule) and the state's resets at uplift and
    rest. Returns the new state and whether rocking ends at the impact."""
    theta, theta_dot, base_state = y
    e, _ = restitution(block, base)
    rest = rests_at_impact(
        block,
        e,
        theta_dot**2,
        opts.rest_tolerance,
        lambda window: base_acceleration_bound(t, window, base_state, base, motion),
        motion.gravity(t),
        (lambda w: motion.gravity_bound(t, t + w)) if has_vertical(motion) else None,
    )
    post_theta_dot, post_base = impact(block, base, theta_dot, base_state, rest)
    theta_dot = jnp.where(ev.impact, post_theta_dot, theta_dot)
    if base_state is not None:
        base_state = jnp.where(ev.impact, post_base, base_state)
        base_state = base.at_transition(base_state, ev.base_peak)
    theta = jnp.where(ev.impact | ev.uplift | ev.settled, 0.0, theta)
    theta_dot = jnp.where(ev.settled, 0.0, theta_dot)
    return (theta, theta_dot, base_state), rest


def _next_phase(c: Carry, ev: _Events, rest, t, y, block, base, motion):
    """The phase and sign that follow, and whether rocking starts here (an
    uplift, or an impact that ends rocking while the base still uplifts)."""
    holds, rules = _holds(ev, rest), [r for r in EVENT_TABLE if r.phase is not None]
    phase = first_true(
        [holds[r.event] for r in rules], [r.phase for r in rules], c.phase
    )
    sign = jnp.where(ev.uplift, jnp.where(ev.towards_plus, 1.0, -1.0), c.sign)
    sign = jnp.where(ev.impact & ~rest, -c.sign, sign)
    again, again_sign = _uplift_now(t, y, phase, block, base, motion)
    phase = jnp.where(again, Phase.RISING, phase)
    sign = jnp.where(again, again_sign, sign)
    return phase, sign, ev.uplift | again


def _event_kind(ev: _Events, rest, failed, still):
    """The segment's `EventKind`: a failure first, then the event table's,
    then QUIET (`still`), else END."""
    holds = _holds(ev, rest)
    return first_true(
        [failed] + [holds[r.event] for r in EVENT_TABLE] + [still],
        [EventKind.FAILURE] + [r.kind for r in EVENT_TABLE] + [EventKind.QUIET],
        EventKind.END,
    )


def can_overturn(phase, sign, y, block, base):
    """Whether the block may still overturn (or uplift) once the ground is
    still: not on a fixed base where it rests, or rocks below the separatrix
    on the near side of its corner (energy conserved between impacts and lost
    at each: x = sin((alpha - s theta) / 2) > 0 and x^2 > (theta' / 2p)^2,
    as `_free.free_rocking_ready` reads it)."""
    if not fixed_base(base):
        return jnp.asarray(True)
    x, _ = sincos(0.5 * (block.alpha - sign * y[0]))
    below = (x > 0) & (x * x > (y[1] / (2.0 * block.p)) ** 2)
    return (phase != Phase.TRANSLATION) & ~below


def _advance(
    c: Carry,
    end: _SegmentEnd,
    ev: _Events,
    y,
    rest,
    sol,
    block,
    base,
    motion,
    duration,
    opts,
) -> Carry:
    """The carry after the segment: the next phase, running maxima, counts,
    and whether the analysis is over."""
    t, cut = end.t, end.cut
    phase, sign, started = _next_phase(c, ev, rest, t, y, block, base, motion)
    theta, base_state = y[0], y[2]
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
    args = Args(
        block, base, motion, phase, sign, max_u, t >= motion.end_time, c.theta_ref
    )
    still = ev.quiet | (quiet(y, args) <= 0)
    max_theta = jnp.where(ev.overturn, 0.5 * jnp.pi, max_theta)
    steps = sol.stats["num_steps"]
    over = end.reached_end & ~end.event & (t >= lane_window(motion, duration, opts))
    # Run until decided (`SolverOptions.until_decided`), the window's end
    # leaves the fate open unless the block can no longer overturn: also where
    # the base still moves, too weakly to lift it (its max |u| may still rise
    # within its bound, as after any window).
    open_fate = can_overturn(phase, sign, y, block, base) & ~still & ~ev.overturn
    open_fate = open_fate & ~never_uplifts(y, args)
    undecided = over & opts.until_decided & open_fate
    # Free flight where its condition fired, or where g_eff is <= 0 after the
    # event (an uplift located where g_eff, and with it the uplift level,
    # reaches 0: the condition then starts at <= 0 and never fires).
    flight = ev.flight
    if has_vertical(motion):
        flight = flight | (motion.gravity(t) <= 0)
    new = Carry(
        t=t,
        y=y,
        phase=phase,
        sign=sign,
        max_theta=max_theta,
        max_u=max_u,
        impacts=c.impacts + ev.impact.astype(c.impacts.dtype),
        uplift_time=jnp.where(jnp.isnan(c.uplift_time) & started, t, c.uplift_time),
        rocked=c.rocked | started,
        overturned=c.overturned | ev.overturn,
        status=jnp.where(
            flight,
            Status.FREE_FLIGHT,
            jnp.where(
                undecided & (end.status == Status.SUCCESS),
                Status.UNDECIDED,
                end.status,
            ),
        ),
        segments=c.segments + jnp.where(cut, 0, 1),
        steps=c.steps + steps,
        segment_steps=jnp.where(cut, end.segment_steps, 0),
        done=ev.overturn | flight | end.failed | over | still,
        theta_ref=jnp.where(cut, c.theta_ref, sign * theta),
        dt=jnp.where(steps > 0, (t - c.t) / jnp.maximum(steps, 1), c.dt),
        kind=_event_kind(ev, rest, end.failed, still),
        t_limit=jnp.where(end.event | (t >= c.t_limit), jnp.inf, c.t_limit),
        quiet_end=c.quiet_end,
        search_from=c.search_from,
        start_conditions=c.start_conditions,
        slid=c.slid,
    )
    if c.slid is None:
        return new
    # At an impact, in the impulses; after any event, in the phase that
    # follows (whose condition may start at <= 0).
    slid = (
        c.slid
        | ev.slide
        | (ev.impact & (block.friction < impact_friction(block, base)))
    )
    new = eqx.tree_at(lambda n: n.slid, new, slid)
    return eqx.tree_at(lambda n: n.slid, new, slides_now(new, block, base, motion))


def _merge_redo(c: Carry, new: Carry, active, redo, limit) -> Carry:
    """A frozen lane keeps its carry; a redo too, but for its limit and steps
    (its `kind` is still the event that began the segment, which the redo
    begins again: `segment_args` reads it)."""
    redone = eqx.tree_at(
        lambda c: (c.t_limit, c.steps),
        c,
        (jnp.where(redo, limit, c.t_limit), jnp.where(redo, new.steps, c.steps)),
    )
    return jax.tree_util.tree_map(
        lambda n, r: jnp.where(active & ~redo, n, r), new, redone
    )


def transition(c: Carry, sol, block, base, motion, duration, opts, limit=None) -> Carry:
    """Apply what ended the segment: uplift, apex, impact map, overturn, ...

    An event that is not the earliest root in its step (where several fire,
    Diffrax takes the first in order) is not applied: the segment is redone
    from its start up to `limit` (`redo_limit`, computed here from the
    conditions at the segment's start unless given), where the earlier root
    fires alone. No redo inside a redo, nor within 2 `REDO_MARGIN` of the
    segment's start: roots closer than that end as one event (the first in
    order).
    """
    active = is_active(c, opts)
    end = _classify_end(c, sol, motion, duration, opts, active)
    if limit is None:
        _, args, named, *_ = segment_setup(c, block, base, motion, duration, opts)
        conditions = jax.tree_util.tree_leaves(named)
        limit = redo_limit(
            c.t,
            end.t,
            [~m for m in sol.event_mask],
            [cond(c.t, c.y, args) for cond in conditions],
            [cond(end.t, end.y, args) for cond in conditions],
        )
    redo = active & end.event & jnp.isfinite(limit) & jnp.isinf(c.t_limit)
    redo = redo & (end.t - 2.0 * REDO_MARGIN > c.t)
    # The solver's mask holds the conditions present, in order: named again.
    conditions = jax.tree_util.tree_structure(event_conditions(block, base, motion))
    mask = jax.tree_util.tree_unflatten(conditions, list(sol.event_mask))
    slides = None
    if mask.slide is not None:
        args = segment_args(c, block, base, motion, end.t)
        slides = checks_friction(args) & (
            slide_margin(end.t, end.y, args) <= corner_margin(end.y, args)
        )
    ev = _decode(c, mask, end.event, end.y[0], slides)
    y, rest = _apply_jumps(ev, end.t, end.y, block, base, motion, opts)
    new = _advance(c, end, ev, y, rest, sol, block, base, motion, duration, opts)
    return _merge_redo(c, new, active, redo, limit)


def moves_on(c: Carry, t, base_state, failed, base, motion, duration, opts):
    """Whether a flat-loop step of one solver step that ends at t in
    `base_state` with no event only moves the state on: its lane is active,
    the solver did not fail (`failed`), the step ends before the segment's
    end and within `max_steps`, and the base's `at_transition` keeps its
    state (it does not `turns_back`). `transition` then reduces to `move_on`."""
    active = is_active(c, opts)
    cut = t < segment_end(c, motion, duration, opts)[1]
    kept = True if base_state is None else ~base.turns_back(base_state)
    return active & ~failed & cut & (c.segment_steps < opts.max_steps) & kept


def move_on(c: Carry, t, y, block, base, motion, quiet_now=None) -> Carry:
    """`transition` after a step that `moves_on`: the new time and state (which
    the base's `at_transition` keeps), max |theta|, the step counts, and
    whether nothing can happen any more (`quiet` <= 0; `quiet_now` if known).
    The next step `dt` is the caller's."""
    theta = y[0]
    if quiet_now is None:
        quiet_now = quiet(y, segment_args(c, block, base, motion, t))
    still = quiet_now <= 0
    kind = jnp.where(still, EventKind.QUIET, EventKind.END).astype(c.kind.dtype)
    return eqx.tree_at(
        lambda c: (
            c.t,
            c.y,
            c.max_theta,
            c.steps,
            c.segment_steps,
            c.done,
            c.kind,
            c.t_limit,
        ),
        c,
        (
            t,
            y,
            jnp.maximum(c.max_theta, jnp.abs(theta)),
            c.steps + 1,
            c.segment_steps + 1,
            still,
            kind,
            jnp.where(t >= c.t_limit, jnp.inf, c.t_limit),
        ),
    )


def response(c: Carry, block, base, opts) -> Response:
    status = jnp.where(c.done, c.status, Status.MAX_SEGMENTS)
    status = jnp.where(c.status != Status.SUCCESS, c.status, status)
    # |theta| beyond pi / 2 without the overturn event: an event was missed,
    # and nothing after it can be trusted.
    lost = ~c.overturned & (c.max_theta > 0.5 * jnp.pi)
    status = jnp.where(lost & (status == Status.SUCCESS), Status.SOLVER_FAILED, status)
    # Outside the model, where it ends as it would: the base reaches its
    # capacity (an isolator without its stop) or its geometry's limit, or the
    # block slides.
    final = (status == Status.SUCCESS) | (status == Status.UNDECIDED)
    limits = [base.geometric_limit]
    if base.capacity is not None and base.stop is None:
        limits.append(base.capacity)
    for limit in limits:
        if limit is not None:
            reached = final & (c.max_u >= limit)
            status = jnp.where(reached, Status.CAPACITY_EXCEEDED, status)
            final = final & ~reached
    if c.slid is not None:
        status = jnp.where(c.slid & final, Status.SLIDING, status)
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


def check_base_and_motion(base, motion):
    """`ValueError` unless `base` is an isolator and `motion` a ground motion."""
    if not isinstance(base, AbstractIsolator):
        raise ValueError(
            "`base` must be an isolator, a jaxrock.AbstractIsolator (FixedBase, "
            "LinearIsolator, FrictionPendulum, BilinearIsolator, "
            "SphericalRollingIsolator, ConicalRollingIsolator, "
            "IntegratedFrictionPendulum or a subclass of your own), got "
            f"{type(base).__name__}"
        )
    if not isinstance(motion, AbstractGroundMotion):
        raise ValueError(
            "`motion` must be a ground motion, a jaxrock.AbstractGroundMotion "
            "(MPPulse, SinePulse, Record, one of these with a vertical part, or "
            f"a subclass of your own), got {type(motion).__name__}"
        )
    check_declared_shapes(base)
