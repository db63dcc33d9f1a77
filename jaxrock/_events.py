"""Event conditions of the segment loop and the root finder that locates them.

Every condition is positive inside its phase and is armed with
`direction=False` (it fires when it goes from > 0 to <= 0 between two step
ends), so a segment that starts exactly on a zero does not fire again at once.

| phase       | "angle" fires at                  | "rate" fires at                  |
|-------------|-----------------------------------|----------------------------------|
| TRANSLATION | u'' + x_g'' = -g tan(alpha): s=+1 | u'' + x_g'' = +g tan(alpha): s=-1 |
| RISING      | s theta = pi / 2: overturn        | theta' = 0: apex                  |
| FALLING     | theta = 0: impact                 | theta' = 0: rising again          |

"base" (isolated bases only) fires where |u| has a local maximum above the
running maximum, so max |u| is an exact extremum, not a sampled one (a friction
pendulum with z in closed form fires at every reversal of u' instead, see
`condition_reversal`). "quiet"
(isolated bases only) ends the analysis once the ground is still and the base's
energy can neither uplift the block nor raise max |u| (the fixed base needs no
event: a block at rest there after the excitation stays at rest).
"slide" (blocks with a `friction` only) fires where the friction needed to
hold the block reaches what its interface gives (`condition_slide`).
"stop" (isolators with a `stop`) fires where the base meets or leaves it
(`condition_stop`). "flight" (under vertical ground motion only) fires where
g + a_v(t) reaches 0 (`condition_flight`).
"guard" catches a phase begun on the wrong side of a near double root of theta'
(see `condition_guard`). Diffrax lets the first condition in PyTree order win
when several fire in one step; `transition` then redoes the segment up to
just before that event if another condition's root came earlier.
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float

from ._dynamics import (
    STOP_ROUNDING,
    Args,
    Phase,
    absolute_base_acceleration,
    contact_forces,
    rest_level,
    uplift_level,
)
from ._misc import GRAVITY


def _by_phase(phase, translation, rising, falling):
    return jnp.where(
        phase == Phase.TRANSLATION,
        translation,
        jnp.where(phase == Phase.RISING, rising, falling),
    )


def condition_angle(t, y, args: Args, **kwargs):
    del kwargs
    theta, _, base_state = y
    a_abs = absolute_base_acceleration(
        t, base_state, args.base, args.motion, args.in_stop
    )
    s_theta = args.sign * theta
    return _by_phase(
        args.phase,
        a_abs + uplift_level(args.block, args.motion.gravity(t)),
        0.5 * jnp.pi - s_theta,
        s_theta,
    )


def condition_rate(t, y, args: Args, **kwargs):
    del kwargs
    _, theta_dot, base_state = y
    a_abs = absolute_base_acceleration(
        t, base_state, args.base, args.motion, args.in_stop
    )
    s_theta_dot = args.sign * theta_dot
    return _by_phase(
        args.phase,
        uplift_level(args.block, args.motion.gravity(t)) - a_abs,
        s_theta_dot,
        -s_theta_dot,
    )


def _free_vibration_margins(y, args: Args):
    """(bound of |u| - max |u| so far, bound of |F / M| - the block's rest
    level) over the base's free vibration from `y`, where they hold: ground
    still and block in translation (else (1, 1)). Each is <= 0 where the
    base's energy is too low to raise max |u|, or to uplift the block."""
    u_bound, f_bound = args.base.free_vibration_bounds(y[2])
    level = rest_level(args.block, args.slid)
    lift = f_bound - level
    if args.base.stop is not None:
        # A base that may reach its stop has no force bound: the margin is
        # also > 0 while u's bound reaches the stop (continuous, so that it
        # has a root to locate, where the bound leaves the stop).
        lift = jnp.maximum(lift, level * (u_bound / args.base.capacity - 1.0))
    # Armed per segment (not by t >= end_time inside one): a condition that jumped
    # within a segment would be "located" at the jump, with a meaningless
    # derivative.
    armed = (args.phase == Phase.TRANSLATION) & args.ground_still
    return (
        jnp.where(armed, u_bound - args.max_base_displacement, 1.0),
        jnp.where(armed, lift, 1.0),
    )


def quiet(y, args: Args):
    """<= 0 when nothing can happen any more: ground still, block in translation,
    and the base's energy too low to uplift it or to raise max |u|."""
    return jnp.maximum(*_free_vibration_margins(y, args))


def never_uplifts(y, args: Args):
    """Whether the block can never uplift again (nor overturn): ground still,
    block in translation, and the base's energy too low to uplift it, though
    the base may still move (and raise max |u|, within its bound)."""
    return _free_vibration_margins(y, args)[1] <= 0


def condition_quiet(t, y, args: Args, **kwargs):
    del t, kwargs
    return quiet(y, args)


# The guard's margin (rad): well above the angle error of a located apex.
GUARD = 1e-9


def condition_guard(t, y, args: Args, **kwargs):
    """Catches a rocking phase that began on the wrong side of a (near) double root.

    An apex or a reversal located where theta' only touches zero leaves the next
    phase's derivative condition starting at <= 0, so it could never fire and
    the block would move the other way unwatched. The guard fires when s theta
    leaves the angle where the phase began by GUARD in the wrong direction:
    below it while RISING, above it while FALLING.
    """
    del t, kwargs
    s_theta = args.sign * y[0]
    return jnp.where(
        args.phase == Phase.RISING,
        s_theta - args.theta_ref + GUARD,
        jnp.where(args.phase == Phase.FALLING, args.theta_ref + GUARD - s_theta, 1.0),
    )


def condition_base(t, y, args: Args, **kwargs):
    """g = max(d|u|/dt, max|u| so far - |u| - |u'| H) (m/s, m): <= 0 at a new
    maximum of |u|, and at the end of a step that passed one.

    H (`Args.step_bound`, s) bounds the steps. A step that passes a peak P
    above max|u| and ends, moving inward, with |u| below max|u| again ends
    at g < 0 all the same: |u| >= P - |u'| H there while |u''| keeps its
    sign past the peak. Its root is the peak (d|u|/dt = 0). The cost: an
    event at a reversal of u within about |u''| H^2 / 2 below max|u|, which
    leaves max|u| as it was. After the ground stops (H = inf), every
    reversal of u outward is an event.

    In a segment that a located peak began (`Args.peak_time`), H is at most
    a third of the time since: just past that peak, max|u| - |u| - |u'| H
    is then about |u''| s^2 / 6 > 0 (s after it) rather than < 0, and g
    fires only at a new peak.
    """
    del kwargs
    u, u_dot = y[2][0], y[2][1]
    outward = jnp.sign(u) * u_dot
    since = jnp.where(jnp.isnan(args.peak_time), jnp.inf, t - args.peak_time)
    step = jnp.minimum(args.step_bound, since / 3.0)
    bounded = jnp.isfinite(step)
    reach = jnp.abs(u_dot) * jnp.where(bounded, step, 0.0)
    below = args.max_base_displacement - jnp.abs(u) - reach
    return jnp.where(bounded, jnp.maximum(outward, below), outward)


# A block with a `friction` passes its corner's vertical at s theta =
# alpha (1 + CORNER_ROUNDING), and comes back over it at alpha (1 -
# CORNER_ROUNDING): each located just beyond the corner, so that the segment
# that follows starts on its side of it (`condition_slide`).
CORNER_ROUNDING = 1e-9


def slide_margin(t, y, args: Args):
    """mu R_y - |R_x| (m/s^2, `contact_forces`): <= 0 where the block's
    friction can no longer hold it (or the normal force would pull)."""
    r_x, r_y = contact_forces(t, y, args)
    return args.block.friction * r_y - jnp.abs(r_x)


def corner_margin(y, args: Args):
    """g (alpha (1 + CORNER_ROUNDING) - s theta) (m/s^2): <= 0 once the
    block passes its corner's vertical."""
    corner = args.block.alpha * (1.0 + CORNER_ROUNDING)
    return GRAVITY * (corner - args.sign * y[0])


def checks_friction(args: Args):
    """Whether a segment checks the block's friction: it starts on the near
    side of the corner (`Args.theta_ref`), and the block has not slid."""
    return ~args.slid & (args.theta_ref < args.block.alpha)


def condition_slide(t, y, args: Args, **kwargs):
    """min(`slide_margin`, `corner_margin`): <= 0 where the block's friction
    can no longer hold it, or where it passes its corner's vertical, past
    which it falls over (a fall that slides at its corner still ends on
    the block's side) and its friction is not checked: a step that ends
    past the corner thus ends at whichever comes first, and a slide just
    before the corner is not lost inside it. `transition` tells the two
    apart (`EventKind.SLIDE` or `CORNER`).

    In a segment that starts past the corner (`Args.theta_ref`), g (s theta
    - alpha (1 - CORNER_ROUNDING)): <= 0 where the block comes back over
    its corner (`EventKind.CORNER`), and the next segment checks its
    friction again. Disarmed (1) once the block slid."""
    del kwargs
    margin = jnp.minimum(slide_margin(t, y, args), corner_margin(y, args))
    back = GRAVITY * (args.sign * y[0] - args.block.alpha * (1.0 - CORNER_ROUNDING))
    margin = jnp.where(args.theta_ref < args.block.alpha, margin, back)
    return jnp.where(args.slid, 1.0, margin)


def condition_stop(t, y, args: Args, **kwargs):
    """m + d while the stop pushes, -m + d while it does not (`in_stop`;
    m = `Stop.margin`, d = `STOP_ROUNDING` capacity, in m): <= 0 where the
    stop starts or stops pushing, the kinks of its force (isolators with a
    `stop`): where the base meets the gap, and where a damped stop's push
    ends before the base is back at the gap (or starts again).

    Each touch is located d past it, so that the next segment's condition
    starts at 2d > 0, off the boundary: a base that leaves its stop and
    meets it again within the next step is seen (it would start at 0 to
    rounding). Past the touch by d the stop's force differs by its
    dashpot's over a travel of d (1e-9 of the capacity) at most."""
    del t, kwargs
    margin = args.base.stop.margin(y[2], args.base.capacity)
    near = STOP_ROUNDING * args.base.capacity
    value = jnp.where(args.in_stop, margin, -margin) + near
    if args.stop_armed is None:
        return value
    # Off the stop, its force is 0 along the segment: a step may pass a
    # whole touch (in and out) and end with -m + d > 0 again. As
    # `condition_base` does for a peak of |u|: a step that passed a peak P
    # past the gap ends, moving inward, with |u| >= P - |u'| H > capacity -
    # |u'| H; `stop_passage` is <= 0 there, and its root comes after the
    # touch's (the min's first root is the touch).
    passage = stop_passage(y[2], args)
    return jnp.where(args.stop_armed, jnp.minimum(value, passage), value)


def stop_passage(base_state, args: Args):
    """max(d|u|/dt, capacity - |u| - |u'| H) (m/s, m), H the step bound
    (`Args.step_bound`): <= 0 at the end of a step that may have passed a
    peak of |u| past the stop's gap. Armed in a segment off the stop that
    starts with the base moving out (`Args.stop_armed`)."""
    u, u_dot = base_state[0], base_state[1]
    outward = jnp.sign(u) * u_dot
    h = jnp.where(jnp.isfinite(args.step_bound), args.step_bound, 0.0)
    below = args.base.capacity - jnp.abs(u) - jnp.abs(u_dot) * h
    return jnp.maximum(outward, below)


def condition_flight(t, y, args: Args, **kwargs):
    """g_eff(t) = g + a_v(t) (m/s^2): <= 0 where the ground falls faster than
    gravity, and the block would leave its base (under vertical motion)."""
    del kwargs
    return jnp.broadcast_to(args.motion.gravity(t), jnp.shape(y[0]))


def newton_in_bracket(t, value, slope, lower, upper, inclusive: bool):
    """One Newton step kept in a bracket, for a root of g with g > 0 at `lower`
    and g <= 0 at `upper`: the bracket shrinks to t's side, and a step that
    leaves it (or a zero slope) bisects instead. Returns (t, lower, upper).

    `inclusive`: a step onto a bound is kept (a converged step stays put, and
    the flat loop stops once its steps are below a few ulps), else it bisects.
    """
    positive = value > 0
    lower = jnp.where(positive, t, lower)
    upper = jnp.where(positive, upper, t)
    newton = t - value / jnp.where(slope == 0, 1.0, slope)
    if inclusive:
        inside = (newton >= lower) & (newton <= upper)
    else:
        inside = (newton > lower) & (newton < upper)
    inside = inside & (slope != 0) & jnp.isfinite(newton)
    new = jnp.where(value == 0, t, jnp.where(inside, newton, 0.5 * (lower + upper)))
    return new, lower, upper


# Tolerances of an event's time: the root finder stops, and the flat loop of
# maps counts an event as located, once Newton's step is below
# EVENT_ATOL + EVENT_RTOL |t| (s).
EVENT_RTOL, EVENT_ATOL = 1e-14, 1e-12


class _BracketState(eqx.Module):
    lower: Float[Array, ""]
    upper: Float[Array, ""]
    step: Float[Array, ""]


class BracketedNewton(optx.AbstractRootFinder):
    """Newton's method kept inside a bracket, falling back to bisection.

    For a scalar root in t of a function that is > 0 at `lower` and <= 0 at
    `upper` (Diffrax's `lower`/`upper` options: the step that saw the sign
    change). The function may return a PyTree of scalars of which all but one are
    zero (as Diffrax passes the conditions); they are summed. Terminates when the
    Newton step is below atol + rtol |t|. Plain `optimistix.Newton` can leave
    the bracket and stall near double roots.
    """

    rtol: float
    atol: float
    norm: ClassVar = jnp.abs

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        del fn, args, f_struct, aux_struct, tags
        return _BracketState(
            lower=jnp.asarray(options["lower"], y.dtype),
            upper=jnp.asarray(options["upper"], y.dtype),
            step=jnp.asarray(jnp.inf, y.dtype),
        )

    def step(self, fn, y, args, options, state, tags):
        del options, tags

        def scalar(t):
            value, aux = fn(t, args)
            return sum(jax.tree_util.tree_leaves(value)), aux

        value, slope, aux = jax.jvp(scalar, (y,), (jnp.ones_like(y),), has_aux=True)
        new_y, lower, upper = newton_in_bracket(
            y, value, slope, state.lower, state.upper, inclusive=False
        )
        return new_y, _BracketState(lower, upper, jnp.abs(new_y - y)), aux

    def terminate(self, fn, y, args, options, state, tags):
        del fn, args, options, tags
        scale = self.atol + self.rtol * jnp.abs(y)
        done = (state.step < scale) | (state.upper - state.lower < scale)
        return done, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        del fn, args, options, state, tags, result
        return y, aux, {}
