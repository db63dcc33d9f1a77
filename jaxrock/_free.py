"""Free rocking on a fixed base, in closed form (the tail of a behavior map).

Once the ground is still, a block rocking on a fixed base is Housner's
inverted pendulum: theta'' = -p^2 sin(s alpha - theta) between impacts, and
each impact multiplies theta' by the coefficient applied, e (`restitution`:
the momentum model's, or the block's own). Energy is conserved between
impacts, so the apex, the time to the next impact and whether the
block overturns follow from the state alone. With x = sin((alpha - |theta|) / 2)
and k = sin((alpha - theta_apex) / 2) (the energy: k^2 = x^2 - theta'^2 / (4 p^2)),

    time from the apex to |theta| = (1 / p) int_k^x ds / sqrt((1 - s^2)(s^2 - k^2))
                                  = (2 / p) sqrt(x - k) R_F(A, B, C),
    A = (1 - k^2)(x + k), B = 2 k (1 - x)(1 + k), C = 2 k (1 - k)(1 + x)

(DLMF 19.29.4 with the factors 1 -+ s and s -+ k), where R_F is Carlson's
symmetric elliptic integral; x - k = (x^2 - k^2) / (x + k) has no cancellation.
Maps run the numerical loop to the end of the excitation and finish each
rocking cell here: 28% of a fixed-base map's steps, and most of its events.
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ._dynamics import Phase, restitution, rests_at_impact
from ._model import Carry
from ._results import EventKind
from ._trig import sincos


def carlson_rf(x, y, z, iterations: int = 16):
    """Carlson's R_F(x, y, z) = (1/2) int_0^inf dt / sqrt((t+x)(t+y)(t+z)), for
    x, y, z >= 0 with at most one zero; float64 to a few ulps.

    The duplication theorem brings the arguments together (each step divides
    their spread by 4, once they are of one magnitude: 16 steps cover a ratio of
    1e16 between them), then a fifth-order series (Carlson 1995).
    """

    def duplicate(_, xyz):
        x, y, z = xyz
        sx, sy, sz = jnp.sqrt(x), jnp.sqrt(y), jnp.sqrt(z)
        lam = sx * (sy + sz) + sy * sz
        return 0.25 * (x + lam), 0.25 * (y + lam), 0.25 * (z + lam)

    x, y, z = jax.lax.fori_loop(0, iterations, duplicate, (x, y, z))
    a = (x + y + z) / 3.0
    dx, dy = 1.0 - x / a, 1.0 - y / a
    dz = -(dx + dy)
    e2 = dx * dy - dz * dz
    e3 = dx * dy * dz
    series = 1.0 - e2 / 10.0 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0
    return series / jnp.sqrt(a)


def time_from_apex(p, x, k, gap, iterations: int = 16):
    """Time (s) from the apex (s = k) to s = x in free rocking; `gap` = x - k."""
    one_k = 1.0 - k
    a = (1.0 + k) * one_k * (x + k)
    b = 2.0 * k * (1.0 - x) * (1.0 + k)
    c = 2.0 * k * one_k * (1.0 + x)
    return 2.0 / p * jnp.sqrt(gap) * carlson_rf(a, b, c, iterations)


def _energy(c: Carry, block):
    """x = sin((alpha - |theta|) / 2) and (theta' / 2p)^2 = x^2 - k^2."""
    x, _ = sincos(0.5 * (block.alpha - c.sign * c.y[0]))
    return x, (c.y[1] / (2.0 * block.p)) ** 2


def free_rocking_ready(c: Carry, block, end_time):
    """The lane can be finished in closed form: fixed base, ground still,
    rocking on the near side of the corner (x > 0: |theta| < alpha) and below
    the separatrix (k^2 > 0: it cannot overturn)."""
    x, gap2 = _energy(c, block)
    rocking = c.phase != Phase.TRANSLATION
    return ~c.done & rocking & (c.t >= end_time) & (x > 0) & (x * x > gap2)


def _apex_of(c: Carry, block, ready, x0):
    """Where a `ready` lane is: x now, k of its energy's apex, the time of
    that apex (ahead of a rising lane, behind a falling one), and whether it
    rises."""
    x, gap2 = _energy(c, block)
    k = jnp.sqrt(jnp.where(ready, jnp.maximum(x * x - gap2, 0.0), x0 * x0))
    offset = time_from_apex(block.p, x, k, gap2 / (x + k))
    rising = c.phase == Phase.RISING
    return x, k, c.t + jnp.where(rising, offset, -offset), rising


def free_rocking(c: Carry, block, base, duration, opts, ready) -> Carry:
    """Finish the `ready` lanes (see `free_rocking_ready`) as `simulate`'s
    segment loop would: their apexes and impacts (with the rest rule) up to
    `duration`, a segment each, and max |theta|. Elementwise over any batch
    shape, one impact per iteration of a loop that runs as long as the busiest
    lane needs; other lanes are returned unchanged."""
    p, alpha = block.p, block.alpha
    e, _ = restitution(block, base)
    x0 = jnp.sin(0.5 * alpha)  # x at theta = 0
    limit = opts.max_segments

    def apex_to_impact(k, iterations=16):
        gap2 = x0 * x0 - k * k  # (theta' / 2p)^2 at the impact
        return time_from_apex(p, x0, k, gap2 / (x0 + k), iterations)

    x, k, t_apex, rising = _apex_of(c, block, ready, x0)
    t_impact = t_apex + apex_to_impact(k)
    # The apex ahead of a rising lane is the highest of the rest of the analysis
    # (energy only falls from here), unless `duration` comes first.
    live = ready & (c.segments < limit)
    apex = live & rising
    cut = apex & (t_apex > duration)
    reached = apex & ~cut
    max_theta = jnp.where(
        reached, jnp.maximum(c.max_theta, alpha - 2.0 * jnp.arcsin(k)), c.max_theta
    )

    def going(s):
        return ~s["done"] & (s["segments"] < limit)

    def body(s):
        """The impact at s["t"] (or the window's end first), then the apex;
        or, where they all fall inside the window, every impact down to rest
        (`_impacts_to_rest`)."""
        end = s["t"] > duration
        gap2 = x0 * x0 - s["k"] ** 2
        # theta'-^2 = 4 p^2 (x0^2 - k^2) at the impact.
        theta_dot_squared = 4.0 * p * p * gap2
        rest = ~end & rests_at_impact(block, e, theta_dot_squared, opts.rest_tolerance)
        # After an impact k >= x0 sqrt(1 - e^2): R_F's arguments are of one
        # magnitude, and 6 duplications give full precision.
        k = jnp.sqrt(x0 * x0 - e * e * gap2)
        half = apex_to_impact(k, 6)
        segments = s["segments"] + 1  # the end, or the impact
        bounce = ~end & ~rest & (segments < limit)
        late = s["t"] + half > duration  # the window ends before the apex
        # The chain: m more impacts, the last of them at most 2 half (1 - e^m)
        # / (1 - e) from this one (with a margin for rounding).
        m, counted = _impacts_to_rest(block, e, theta_dot_squared, opts)
        span = 2.0 * half * (1.0 - e**m) / (1.0 - jnp.minimum(e, 1.0 - 1e-16))
        chain = bounce & counted & (s["t"] + span * (1.0 + 1e-9) <= duration)
        chain = chain & (s["segments"] + 2 * m < limit)
        # The apex after a rebound: for a lane that was falling when the
        # ground stopped the highest of the rest of the analysis (the apex of
        # its energy then is behind it). A window that ends before it keeps
        # the rebound's (k, apex time), to find theta at the window's end.
        rebound = going(s) & bounce
        top = jnp.where(rebound & ~late, alpha - 2.0 * jnp.arcsin(k), 0.0)
        first_cut = rebound & late & ~s["cut"]
        new = dict(
            t=s["t"] + 2.0 * half,
            k=k,
            top=jnp.maximum(s["top"], top),
            cut=s["cut"] | first_cut,
            cut_k=jnp.where(first_cut, k, s["cut_k"]),
            cut_apex=jnp.where(first_cut, s["t"] + half, s["cut_apex"]),
            cut_x=jnp.where(first_cut, x0, s["cut_x"]),
            impacts=s["impacts"] + ~end + jnp.where(chain, m, 0),
            segments=segments + bounce + jnp.where(chain, 2 * m - 1, 0),
            done=end | rest | (bounce & late) | chain,
        )
        return jax.tree_util.tree_map(lambda n, o: jnp.where(going(s), n, o), new, s)

    s = dict(
        t=t_impact,
        k=k,
        top=max_theta,
        # A lane whose window ends before an apex: that apex's k and time,
        # and x where theta is 0 on its rise.
        cut=cut,
        cut_k=k,
        cut_apex=t_apex,
        cut_x=x,
        impacts=c.impacts,
        segments=c.segments + apex,  # the apex, or the end before it
        done=~live | cut,
    )
    s = jax.lax.while_loop(lambda s: jnp.any(going(s)), body, s)
    max_theta = _max_theta(p, alpha, s, duration)

    def fields(c):
        return c.max_theta, c.impacts, c.segments, c.done, c.kind

    new = (max_theta, s["impacts"], s["segments"], s["done"], EventKind.END)
    return eqx.tree_at(
        fields, c, tuple(jnp.where(ready, n, o) for n, o in zip(new, fields(c)))
    )


def _max_theta(p, alpha, s, duration):
    """max |theta| of the lanes of `free_rocking`'s loop state `s`: its apexes
    (s["top"]), or theta at `duration` where the window ends on a rise
    from x = s["cut_x"] toward the apex s["cut_k"] at s["cut_apex"], by
    bisection on the time from the apex (64 halvings)."""
    k = s["cut_k"]

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        late = time_from_apex(p, mid, k, mid - k) > s["cut_apex"] - duration
        return jnp.where(late, lo, mid), jnp.where(late, mid, hi)

    x_end = jax.lax.cond(
        jnp.any(s["cut"]),
        lambda: jax.lax.fori_loop(0, 64, bisect, (k, s["cut_x"]))[0],
        lambda: k,
    )
    at_end = alpha - 2.0 * jnp.arcsin(x_end)
    return jnp.where(s["cut"], jnp.maximum(s["top"], at_end), s["top"])


def _impacts_to_rest(block, e, theta_dot_squared, opts):
    """(m, counted): the impacts after one at theta'^2 = `theta_dot_squared`
    until the rest rule ends rocking in free rocking, and whether m is
    counted (e < 1 and m checked with `rests_at_impact` itself at m - 1 and
    m; m is 0 where it is not).

    Each impact multiplies theta'^2 by e^2, and the rule holds at the first
    impact whose rise e^2 theta'^2 / (2 p^2 sin alpha) is below
    `rest_tolerance` alpha: m = floor(log(tol alpha / rise_0) / log(e^2)) + 1.

    The half-cycles between them shrink at least as fast, so a chain of m
    impacts lasts at most 2 half_1 (1 - e^m) / (1 - e), half_1 the
    half-cycle after the first: the time from an apex theta_a to the impact
    over the impact's speed v is (1 / (2 p^2)) int_0^1 ds / (F sqrt(R(s))),
    with F = int_0^1 sin(alpha - theta_a s) ds and R(s) = int_s^1
    sin(alpha - theta_a s') ds' / F. It grows with theta_a: F falls, and so
    does R, as the weight of sin(alpha - theta_a s) moves toward small s
    (its ratio at two apexes is monotone in s). The next half-cycle, at the
    speed e v, is thus at most e times this one.
    """

    def rests(j):
        return rests_at_impact(
            block, e, theta_dot_squared * e ** (2.0 * j), opts.rest_tolerance
        )

    e_below_one = jnp.clip(e, 1e-300, 1.0 - 1e-16)  # (for the logarithm)
    sin_alpha = block.b / block.size
    rise = e_below_one**2 * theta_dot_squared / (2.0 * block.p**2 * sin_alpha)
    ratio = opts.rest_tolerance * block.alpha / rise
    m = jnp.floor(jnp.log(ratio) / jnp.log(e_below_one**2)) + 1.0
    m = jnp.clip(jnp.nan_to_num(m), 1.0, 1e6)
    counted = (e > 0) & (e < 1) & ~rests(0.0) & rests(m) & ~rests(m - 1.0)
    return jnp.where(counted, m, 0.0).astype(jnp.int32), counted
