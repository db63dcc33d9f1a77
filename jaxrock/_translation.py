"""A linear isolator's base in translation under a record, in closed form.

While the block rests on it (in translation), the base of a `LinearIsolator`
is a linear oscillator, u'' + 2 xi omega u' + omega^2 u = -x_g''(t), and a
record's x_g'' is linear between its samples: the classic exact method for
records gives its state at every sample. The state is y = y_p + h, with y_p
the particular response (from rest at t = 0) and h a free vibration, whose
energy E = h'^2 / 2 + omega^2 h^2 / 2 never grows (`free_vibration`).

`TranslationTables` holds, for every sample k (times t_k = k dt) of a record:
y_p(t_k); the largest |u_p| over [0, t_k] (its peaks between samples located
on the closed form); and, for every sample interval [t_k, t_k+1], bounds of
the absolute base acceleration |A_p| = |x_g'' + u_p''| and of |u_p| over it,
as tables of their maxima over ranges of 2^l intervals (`RecordSignal.with_peaks`'
form). A bound is the larger end value plus dt^2 / 8 max |g''| (the error of
linear interpolation); g'' = u_p'' or A_p'' is that of a free vibration
started from (u_p'', u_p''') at t_k, bounded by its energy.

A block at rest on the base then skips to the first interval where
|A_p| + max |A_h| could reach its uplift level (or |u| a new maximum): the
flat loop of maps jumps there in one step (`_flat._rest_jump`).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._misc import range_maxima

# dt^2 / 8: the largest |g - linear interpolation| over an interval, per
# unit of max |g''|.
_INTERPOLATION = 0.125


def free_vibration(omega, damping, state, tau):
    """(u, u') after tau (s) of free vibration from `state` = (u, u'):
    exp(S tau) state, S = [[0, 1], [-omega^2, -2 xi omega]], for any
    damping ratio xi >= 0 (under-, critically and over-damped)."""
    mu = damping * omega
    nu2 = omega**2 * (damping**2 - 1.0)
    w = jnp.sqrt(jnp.abs(nu2))
    under = nu2 < 0
    decay = jnp.exp(-mu * tau)
    # exp(-mu tau) (cosh(w tau), sinh(w tau) / w), over-damped without overflow.
    grow, fall = jnp.exp((w - mu) * tau), jnp.exp(-(w + mu) * tau)
    safe_w = jnp.where(w > 0, w, 1.0)
    c = jnp.where(under, decay * jnp.cos(w * tau), 0.5 * (grow + fall))
    s = jnp.where(
        w > 0,
        jnp.where(under, decay * jnp.sin(w * tau), 0.5 * (grow - fall)) / safe_w,
        decay * tau,
    )
    u, v = state[..., 0], state[..., 1]
    return jnp.stack(
        [(c + mu * s) * u + s * v, -(omega**2) * s * u + (c - mu * s) * v], axis=-1
    )


def free_vibration_bounds(omega, damping, state):
    """Bounds of |u| (m) and of |omega^2 u + 2 xi omega u'| (m/s^2) over a
    free vibration from `state` = (u, u'): E = u'^2 / 2 + omega^2 u^2 / 2
    decays (E' = -2 xi omega u'^2), and |u| <= sqrt(2E) / omega,
    |omega^2 u + 2 xi omega u'| <= omega sqrt(2E) sqrt(1 + 4 xi^2)."""
    # (sqrt of at least 1e-300: a finite derivative at rest)
    amplitude = jnp.sqrt(
        jnp.maximum(state[..., 1] ** 2 + (omega * state[..., 0]) ** 2, 1e-300)
    )
    return amplitude / omega, omega * amplitude * jnp.sqrt(1.0 + 4.0 * damping**2)


class TranslationTables(eqx.Module):
    """The particular response of a linear isolator's base in translation to
    a record (or to each record of a suite: leading axes).

    `states`: (u_p, u_p') at the samples (m, m/s). `displacement_max`: max
    |u_p| over [0, t_k] (m). `acceleration_peaks` and `displacement_peaks`:
    bounds of |A_p| (m/s^2) and |u_p| (m) over the intervals [k, k + 2^l)
    (levels l, as `RecordSignal.peaks`); inf from the record's last sample on.
    `scaled`: of the records' samples with their factors multiplied out
    (else read times the factors, see `RecordSignal.with_translation`).
    """

    states: Float[Array, "*records n 2"]
    displacement_max: Float[Array, "*records n"]
    acceleration_peaks: Float[Array, "*records levels n"]
    displacement_peaks: Float[Array, "*records levels n"]
    scaled: bool = eqx.field(static=True, default=False)


def _one_record(omega, damping, samples, dt, length):
    """`TranslationTables` of one record (samples of shape (n,))."""
    mu = damping * omega
    a0, a1 = samples[:-1], samples[1:]
    slope = (a1 - a0) / dt

    def particular(a, s):
        # u_q = alpha + beta tau solves u'' + 2 mu u' + omega^2 u = -(a + s tau).
        beta = -s / omega**2
        alpha = (-a - 2.0 * mu * beta) / omega**2
        return alpha, beta

    def sample_step(y, x):
        a, s = x
        alpha, beta = particular(a, s)
        start = jnp.stack([alpha, beta])
        end = jnp.stack([alpha + beta * dt, beta])
        y1 = end + free_vibration(omega, damping, y - start, dt)
        return y1, y1

    zero = jnp.zeros(2, dtype=samples.dtype)
    _, later = jax.lax.scan(sample_step, zero, (a0, slope))
    states = jnp.concatenate([zero[None], later])
    u, v = states[:, 0], states[:, 1]
    accel = -(omega**2 * u + 2.0 * mu * v)  # A_p = x_g'' + u_p''
    # u_p'' and u_p''' at the start of each interval: the free vibration that
    # A_p'' and u_p'' follow over it.
    u2 = accel[:-1] - a0
    u3 = -slope - 2.0 * mu * u2 - omega**2 * v[:-1]
    u2_bound, a2_bound = free_vibration_bounds(
        omega, damping, jnp.stack([u2, u3], axis=-1)
    )
    margin = _INTERPOLATION * dt**2
    inside = jnp.arange(samples.shape[0] - 1) < length - 1
    a_env = jnp.maximum(jnp.abs(accel[:-1]), jnp.abs(accel[1:])) + margin * a2_bound
    u_env = jnp.maximum(jnp.abs(u[:-1]), jnp.abs(u[1:])) + margin * u2_bound
    a_env = jnp.append(jnp.where(inside, a_env, jnp.inf), jnp.inf)
    u_env = jnp.append(jnp.where(inside, u_env, jnp.inf), jnp.inf)

    # max |u_p| over each interval: its ends, and a peak where u_p' changes
    # sign (Newton on the closed form, from the secant).
    def peak(y0, a, s, v1):
        alpha, beta = particular(a, s)
        h0 = y0 - jnp.stack([alpha, beta])

        def at(tau):
            return jnp.stack([alpha + beta * tau, beta]) + free_vibration(
                omega, damping, h0, tau
            )

        def newton(_, state):  # kept in the bracket [lower, upper], else bisection
            tau, lower, upper = state
            y = at(tau)
            u_ddot = -(a + s * tau) - (omega**2 * y[0] + 2.0 * mu * y[1])
            same = y[1] * y0[1] > 0  # u_p' has the sign it has at t_k
            lower, upper = jnp.where(same, tau, lower), jnp.where(same, upper, tau)
            new = tau - y[1] / jnp.where(u_ddot == 0, 1.0, u_ddot)
            inside = (new > lower) & (new < upper) & (u_ddot != 0)
            return jnp.where(inside, new, 0.5 * (lower + upper)), lower, upper

        tau = dt * y0[1] / jnp.where(y0[1] == v1, 1.0, y0[1] - v1)
        start = (jnp.clip(tau, 0.0, dt), jnp.zeros_like(dt), dt)
        tau, _, _ = jax.lax.fori_loop(0, 12, newton, start)
        return jnp.abs(at(tau)[0])

    turns = v[:-1] * v[1:] < 0
    peaks = jax.vmap(peak)(states[:-1], a0, slope, v[1:])
    interval_max = jnp.maximum(
        jnp.maximum(jnp.abs(u[:-1]), jnp.abs(u[1:])), jnp.where(turns, peaks, 0.0)
    )
    interval_max = jnp.where(inside, interval_max, 0.0)
    displacement_max = jnp.concatenate(
        [jnp.zeros(1, samples.dtype), jax.lax.cummax(interval_max)]
    )
    return TranslationTables(
        states,
        displacement_max,
        range_maxima(a_env, jnp.inf),
        range_maxima(u_env, jnp.inf),
    )


def translation_tables(omega, damping, samples, dt, length):
    """`TranslationTables` of a record or suite (`Record.unscaled`, with its
    `dt` and `length` per record): one per row of `samples`, a record at a
    time (`lax.map`, also for one record: a suite's row and the record alone
    get the same tables to the bit, which a `vmap` over the rows did not)."""
    rows = samples.reshape(-1, samples.shape[-1])
    # A record's dt and length (of the unscaled rows: the batch's trailing axes).
    records = rows.shape[0]
    dt = jnp.reshape(dt, -1)[-records:]
    length = jnp.reshape(length, -1)[-records:]
    tables = jax.lax.map(
        lambda row: _one_record(omega, damping, *row), (rows, dt, length)
    )
    return jax.tree_util.tree_map(
        lambda x: x.reshape(samples.shape[:-1] + x.shape[1:]), tables
    )
