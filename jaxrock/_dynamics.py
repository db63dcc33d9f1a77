"""Equations of motion of a block on a base, both regimes in one vector field.

State y = (theta, theta', base state), base state None (fixed base),
(u, u') (linear isolator) or (u, u', z) (friction pendulum). SI units.
The regime enters through `sign`: 0 in pure translation (theta = 0), and
s = sgn(theta) = +1 or -1 while rocking about the corner at x = +b or -b.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._block import Block
from ._isolators import AbstractIsolator
from ._misc import GRAVITY, computed_once
from ._scene import fixed_base
from ._signal import AbstractAcceleration
from ._trig import sincos


class Phase:
    """The segment loop's phases (integer codes, usable under `jit` and `vmap`).

    Rocking is split at each apex (theta' = 0), so that every excursion from
    theta = 0 shows a sign change of its event condition at step ends.
    """

    TRANSLATION = 0  # theta = 0, the block moves with the base
    RISING = 1  # s theta' > 0: |theta| grows
    FALLING = 2  # s theta' < 0: |theta| shrinks towards an impact


class Args(eqx.Module):
    """What the vector field and the event conditions read, besides (t, y)."""

    block: Block
    base: AbstractIsolator
    motion: AbstractAcceleration  # a signal, or one value of x_g'' (`_flat`)
    phase: jnp.ndarray
    sign: jnp.ndarray
    max_base_displacement: jnp.ndarray  # running max |u| so far (m)
    ground_still: jnp.ndarray  # the excitation is over (fixed for a segment)
    theta_ref: jnp.ndarray  # s theta where the rocking phase began (rad)
    # The block slid already (its slide condition is disarmed); None: the
    # block has no `friction`.
    slid: jnp.ndarray | None = None
    # The stop pushes the base (`in_stop`); None: the base has no stop.
    in_stop: jnp.ndarray | None = None
    # A bound of the segment's steps (s; inf: none), and the time of a peak
    # of |u| located at the segment's start (nan: none): `condition_base`.
    step_bound: jnp.ndarray | None = None
    peak_time: jnp.ndarray | None = None
    # Off its stop, whether the segment watches for a step that passes a
    # whole touch (`condition_stop`); None: the base has no stop.
    stop_armed: jnp.ndarray | None = None


def _geometry(block, theta, s):
    """c1 = h cos(theta) + s b sin(theta), s1 = s b cos(theta) - h sin(theta)."""
    sin, cos = sincos(theta)
    return block.h * cos + s * block.b * sin, s * block.b * cos - block.h * sin


def isolator_force(base: AbstractIsolator, state, gravity, against_stop=None):
    """The isolator's force per unit total mass at g_eff = `gravity`
    (m/s^2): a `weight_borne` isolator's force, proportional to the normal
    force M g, times g_eff / g (the paper's N = M g with g -> g_eff); any
    other's as it is; plus its `stop`'s, in a segment against it
    (`against_stop`, the segment's `Args.in_stop`: the dashpot's force jumps
    where the base meets the stop, at the segment's start), else past the
    `capacity`."""
    f = base.force(state)
    if base.weight_borne and not isinstance(gravity, float):
        f = f * (gravity / GRAVITY)
    if base.stop is not None:
        f = f + base.stop.force(state, base.capacity, against_stop)
    return f


def uplift_level(block: Block, gravity):
    """g_eff tan(alpha) (m/s^2): the absolute base acceleration that uplifts
    the block at g_eff = `gravity` (`Block.uplift_acceleration` at g)."""
    return gravity / block.slenderness


def _accelerations(t, y, args: Args):
    """(theta'', u'' (None on a fixed base), x_g'', g_eff) at (t, y)
    (rad/s^2, m/s^2)."""
    theta, theta_dot, base_state = y
    block, base = args.block, args.base
    rocking = args.phase != Phase.TRANSLATION
    s = jnp.where(rocking, args.sign, 1.0)
    c1, s1 = _geometry(block, theta, s)
    ag = args.motion.acceleration(t)
    g = args.motion.gravity(t)
    j = 4.0 / 3.0 * block.size**2
    if fixed_base(base):
        theta_ddot = -(c1 * ag + g * s1) / j
        return jnp.where(rocking, theta_ddot, 0.0), None, ag, g
    f = isolator_force(base, base_state, g, args.in_stop)
    mu = base.block_mass_fraction
    det = j - mu * c1**2
    rhs_u = -ag - mu * s1 * theta_dot**2 - f
    rhs_theta = -c1 * ag - g * s1
    u_ddot_rocking = (j * rhs_u - mu * c1 * rhs_theta) / det
    theta_ddot = (rhs_theta - c1 * rhs_u) / det
    u_ddot = jnp.where(rocking, u_ddot_rocking, -ag - f)
    return jnp.where(rocking, theta_ddot, 0.0), u_ddot, ag, g


def vector_field(t, y, args: Args):
    """Lagrange's equations of Sec. 2 of the paper (docs/model.md), per unit m.

    Rocking:  u'' + mu c1 theta'' + mu s1 theta'^2 + f = -x_g''
              c1 u'' + (4/3) r^2 theta'' + g s1     = -c1 x_g''
    with mu = m / M and f = F / M; translation: u'' = -f - x_g'', theta'' = 0.
    Fixed base: theta'' = -(3 / (4 r^2)) (c1 x_g'' + g s1). Under vertical
    ground motion g is g_eff(t) = g + a_v(t) (`AbstractAcceleration.gravity`),
    in these and in a `weight_borne` isolator's force.
    """
    theta_dot, base_state = y[1], y[2]
    rocking = args.phase != Phase.TRANSLATION
    theta_ddot, u_ddot, _, _ = _accelerations(t, y, args)
    if u_ddot is None:
        u_ddot = jnp.zeros_like(theta_dot)  # (a fixed base has no base state)
    return (
        jnp.where(rocking, theta_dot, 0.0),
        theta_ddot,
        args.base.rates(base_state, u_ddot),
    )


def contact_forces(t, y, args: Args):
    """(R_x, R_y) per unit m (m/s^2): the horizontal and the normal force of
    the base on the block, from the motion of its centre of mass.

    Relative to the pivot the centre of mass is at X = -s1, Y = c1
    (`_geometry`), so X' = c1 theta', Y' = s1 theta' and
    R_x = u'' + x_g'' + c1 theta'' + s1 theta'^2 and
    R_y = g + s1 theta'' - c1 theta'^2; in translation R_x = u'' + x_g'',
    R_y = g (g_eff under vertical ground motion)."""
    theta, theta_dot = y[0], y[1]
    rocking = args.phase != Phase.TRANSLATION
    c1, s1 = _geometry(args.block, theta, jnp.where(rocking, args.sign, 1.0))
    theta_ddot, u_ddot, ag, g = _accelerations(t, y, args)
    a_base = ag if u_ddot is None else u_ddot + ag
    w2 = theta_dot**2
    return (
        a_base + c1 * theta_ddot + s1 * w2,
        g + s1 * theta_ddot - c1 * w2,
    )


def impact_friction(block: Block, base: AbstractIsolator):
    """The coefficient of friction that an impact needs (-): the ratio
    |P_x| / P_y of the impulses of the base on the block at the new corner.

    With theta'+ = e theta'- the block's centre of mass changes its velocity
    by h (theta'+ - theta'-) horizontally and b (1 + e) |theta'-| upwards,
    and the base's by -mu h (theta'+ - theta'-) (`impact`), so
    |P_x| / P_y = (1 - mu) (h / b) (1 - e) / (1 + e), whatever theta'-. An
    impact after which the rest rule ends rocking stands for a chatter of
    such impacts: the same ratio, with e clipped at 0 (a block that stops
    dead)."""
    e = jnp.maximum(restitution(block, base)[0], 0.0)
    mu = base.block_mass_fraction
    return (1.0 - mu) * block.slenderness * (1.0 - e) / (1.0 + e)


def in_stop(base_state, base):
    """Whether the base's `stop` pushes it (`Stop.margin` > 0), for the
    stop's force and event condition of the segment that starts in
    `base_state`; None without a stop. A located touch lies
    `STOP_ROUNDING` past the margin's root (`condition_stop`), on the side
    it moves to."""
    if base.stop is None:
        return None
    return base.stop.margin(base_state, base.capacity) > 0


# Of the capacity: the width of the gap's rounding after a located touch.
STOP_ROUNDING = 1e-9


def rest_level(block: Block, slid, gravity=GRAVITY):
    """|u'' + x_g''| (m/s^2) below which nothing happens to a block at rest on
    its base: it uplifts at g tan(alpha) and, with a `friction` mu, until it
    has slid (`slid`; None without a friction), slides at mu g. The level of
    every shortcut that skips a block at rest, at g_eff = `gravity`: under a
    vertical motion its least value (`AbstractSignal.least_gravity`), or the
    level at g that the motion scales (`AbstractSignal.level_from`)."""
    level = uplift_level(block, gravity)
    if slid is None:
        return level
    return jnp.where(slid, level, jnp.minimum(level, block.friction * gravity))


def base_acceleration_bound(t, window, base_state, base, motion):
    """A bound of |u'' + x_g''| over [t, t + window] (m/s^2): on a fixed base
    the ground's (`AbstractSignal.acceleration_bound`); on an isolator
    the base's acceleration at t, which the isolator's force keeps smooth
    (its rate of change is bounded by the state, and the windows of the rest
    rule last milliseconds)."""
    if fixed_base(base):
        return motion.acceleration_bound(t, t + window)
    return jnp.abs(absolute_base_acceleration(t, base_state, base, motion))


def absolute_base_acceleration(t, base_state, base, motion, against_stop=None):
    """u'' + x_g'' in pure translation (m/s^2): -F / M, or x_g'' on a fixed base."""
    if fixed_base(base):
        a = motion.acceleration(t)
    else:
        a = -isolator_force(base, base_state, motion.gravity(t), against_stop)
    # Read by both uplift conditions and much of the transition.
    return computed_once(a)


def momentum_restitution(block: Block, base: AbstractIsolator):
    """e0 = theta'+ / theta'- of the momentum model at a re-uplift (Eq. 2.13).

    den = 4 m_b h^2 + 4 m_b b^2 + m h^2 + 4 m b^2,
    num = 4 m_b h^2 - 2 m_b b^2 + m h^2 - 2 m b^2; fixed base: 1 - 1.5 sin^2 alpha.
    Returns (e0, den / m_b) with m = 1, written in mu = m / M so that mu = 0 is
    the fixed base.
    """
    mu = base.block_mass_fraction
    h2, b2 = block.h**2, block.b**2
    # Divide num and den by m_b and use m / m_b = mu / (1 - mu).
    ratio = mu / (1.0 - mu)
    den = 4.0 * h2 + 4.0 * b2 + ratio * (h2 + 4.0 * b2)
    num = 4.0 * h2 - 2.0 * b2 + ratio * (h2 - 2.0 * b2)
    return num / den, den


def restitution(block: Block, base: AbstractIsolator):
    """e = theta'+ / theta'- applied at a re-uplift: the momentum model's e0
    (`momentum_restitution`) times the block's `restitution_factor`, or the
    block's `restitution`. Returns (e, den / m_b) (see `momentum_restitution`).
    """
    e0, den = momentum_restitution(block, base)
    return block.applied_restitution(e0), den


def restitution_valid(block: Block, base: AbstractIsolator):
    """e <= 1 for the coefficient applied (traceable): a re-uplift must not
    gain energy. Only a `restitution_factor` can break it, by an amount that
    depends on the block's geometry and the base's mass ratio."""
    e, _ = restitution(block, base)
    return jnp.all(e <= 1.0)


def check_restitution(block: Block, base: AbstractIsolator) -> None:
    """`ValueError` naming `restitution_factor` when f e0 > 1 for concrete
    values (traced ones: `restitution_valid`)."""
    leaves = [block.restitution_factor, block.slenderness, block.size]
    leaves += jax.tree_util.tree_leaves(base)
    if block.restitution_factor is None or any(
        isinstance(x, jax.core.Tracer) for x in leaves
    ):
        return
    with jax.ensure_compile_time_eval():  # (also when called inside `jit`)
        e0 = momentum_restitution(block, base)[0]
    if isinstance(e0, jax.core.Tracer):
        return
    f, e0 = np.asarray(block.restitution_factor), np.asarray(e0)
    fe = f * e0
    bad = ~(fe <= 1.0)
    if np.any(bad):
        k = np.unravel_index(np.argmax(bad), bad.shape) if bad.ndim else ()
        f_k = np.broadcast_to(f, bad.shape)[k]
        e_k = np.broadcast_to(e0, bad.shape)[k]
        raise ValueError(
            f"`restitution_factor` times the momentum model's coefficient e0 must "
            f"be <= 1 (a rebound that gains no energy), got f = {f_k:g} with "
            f"e0 = {e_k:.4g}: f e0 = {f_k * e_k:.4g}. e0 depends on the block's "
            "slenderness and, on an isolated base, on the mass ratio: here f must "
            f"be <= {1.0 / e_k:.4g}"
        )


def rests_at_impact(
    block: Block,
    e,
    theta_dot_squared,
    rest_tolerance,
    lift_bound=None,
    gravity=GRAVITY,
    gravity_bound=None,
):
    """The rest rule, against Zeno chattering: rocking ends at an impact when
    e <= 0, or when

    - the rebound could lift the block by less than `rest_tolerance` alpha:
      the rise (e theta'-)^2 / (2 p^2 sin alpha) of free rocking from
      theta = 0 (linearized), and
    - the base cannot lift the block before the chatter that the rule cuts
      short would end by itself. Under an absolute base acceleration of at
      most L the flights after the impact decelerate at least
      d(L) = p^2 cos(alpha) (g tan(alpha) - L) / g, so the impacts (rebounds
      e^k e theta'-) end within S(L) = 2 e |theta'-| / (d(L) (1 - e)). With
      L0 the base's acceleration at the impact, the rule asks that
      `lift_bound(S)`, a bound of |u'' + x_g''| over the next S seconds, stay
      below (g tan(alpha) + L0) / 2 for S = S((g tan(alpha) + L0) / 2): the
      block then rests at the same time and in the same state as the chatter
      would leave it, and the rule changes nothing but the impacts counted.
      A chatter the base may lift goes on until it is short enough.

    `theta_dot_squared` is theta'-^2; `lift_bound(window)` (m/s^2) bounds the
    base's absolute acceleration over [t, t + window] (window 0: at t); None
    (a base at rest after the excitation) means no base acceleration.

    Under vertical ground motion the rise is that at g_eff = `gravity` (at
    the impact, p^2 = 3 g_eff / (4 r)), and the uplift level is that at the
    least g_eff over twice the window S found at g_eff: with
    `gravity_bound(w)`, a lower bound of g_eff over [t, t + w] (None: no
    vertical motion), the rule asks that S at that level be no longer."""
    p = jnp.sqrt(3.0 * gravity / (4.0 * block.size))  # `Block.p` at g_eff
    rise = e * e * theta_dot_squared / (2.0 * p**2 * block.b / block.size)
    rest = (e <= 0) | (rise < rest_tolerance * block.alpha)
    if lift_bound is None:
        return rest

    def window(threshold):
        """(level, the deceleration, S) at the uplift level `threshold`."""
        level = 0.5 * (threshold + lift_bound(0.0))
        # d(level) = p^2 cos(alpha) (threshold - level) / g, p^2 / g = 3 / (4 r).
        decel = 0.75 * block.h / block.size**2 * (threshold - level)
        s = 2.0 * e * jnp.sqrt(theta_dot_squared) / (decel * (1.0 - e))
        return level, decel, jnp.where(rest & (decel > 0) & (e < 1), s, 0.0)

    if gravity_bound is None:
        level, decel, s = window(block.uplift_acceleration)
        return (e <= 0) | (rest & (decel > 0) & (lift_bound(s) < level))
    _, decel_now, s_now = window(uplift_level(block, gravity))
    horizon = 2.0 * s_now
    level, decel, s = window(uplift_level(block, gravity_bound(horizon)))
    ends = rest & (decel_now > 0) & (decel > 0) & (s <= horizon)
    return (e <= 0) | (ends & (lift_bound(s) < level))


def impact(block, base, theta_dot, base_state, rest):
    """Jump map at theta = 0 (Eqs. 2.13-2.15): post-impact (theta', base state).

    Re-uplift about the other corner: theta'+ = e theta'-, with e applied
    (`restitution`), and u'+ = u'- + m h (theta'- - theta'+) / M: the linear
    momentum M u' + m h theta' of block and base is conserved. With e the
    momentum model's e0 this is Eq. 2.14, u'+ = u'- + 6 m h b^2 theta'- / den
    (m h (1 - e0) / M = 6 m h b^2 / den), the form computed, plus
    m h (e0 - e) theta'- / M (exactly zero for e = e0).
    Rocking ends (`rest`): theta'+ = 0, u'+ = u'- + m h theta'- / M.
    """
    e0, den_per_mb = momentum_restitution(block, base)
    e = block.applied_restitution(e0)
    new_theta_dot = jnp.where(rest, 0.0, e * theta_dot)
    if base_state is None:
        return new_theta_dot, None
    mu = base.block_mass_fraction
    # m / den = (m / m_b) / (den / m_b) and m / M = mu.
    kick_uplift = 6.0 * (mu / (1.0 - mu)) * block.h * block.b**2 / den_per_mb
    kick_uplift = kick_uplift + mu * block.h * (e0 - e)
    kick_rest = mu * block.h
    kick = jnp.where(rest, kick_rest, kick_uplift)
    return new_theta_dot, base_state.at[1].add(kick * theta_dot)
