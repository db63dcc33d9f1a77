"""Fragility: probability of rocking and of overturning against an intensity
measure, over an ensemble of motions, with lognormal fits by maximum likelihood."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.scipy.stats import norm

from ._ground import AbstractGroundMotion, MPPulse, Record
from ._isolators import AbstractIsolator
from ._maps import _batch_shape, behavior_map
from ._misc import GRAVITY, positive
from ._results import Outcome, Status

MEASURES = ("pga", "pgv", "pga_ratio")


def _peaks(motion: AbstractGroundMotion, samples: int = 20001):
    """(PGA in m/s^2, PGV in m/s) of each motion of a batch (1-D arrays)."""
    if isinstance(motion, Record):
        a = np.asarray(motion.samples)
        v = np.concatenate(
            [[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * float(motion.dt))]
        )
        return np.array([np.abs(a).max()]), np.array([np.abs(v).max()])
    shape = _batch_shape(motion)
    flat = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, shape).reshape(-1), motion
    )
    start = np.asarray(flat.t0 - flat.half_duration)
    stop = np.asarray(flat.end_time)
    ts = start[:, None] + (stop - start)[:, None] * np.linspace(0.0, 1.0, samples)
    acc = jax.vmap(lambda m, t: m.acceleration(t))
    vel = jax.vmap(lambda m, t: m.velocity(t))
    t = jnp.asarray(ts)
    pga = np.abs(np.asarray(acc(flat, t))).max(axis=1)
    pgv = np.abs(np.asarray(vel(flat, t))).max(axis=1)
    return pga, pgv


def fit_lognormal(im, failed, steps: int = 2000):
    """Maximum-likelihood lognormal fit, P(failure | IM) = Phi(ln(IM / median) / beta).

    `im` > 0 and `failed` (bool) are 1-D. Returns (median, beta); NaN when every
    or no analysis failed (the likelihood has no maximum then).
    """
    im = np.asarray(im, dtype=float)
    failed = np.asarray(failed, dtype=bool)
    if im.ndim != 1 or failed.shape != im.shape:
        raise ValueError(
            "`im` and `failed` must be 1-D arrays of one length, got shapes "
            f"{im.shape} and {failed.shape}"
        )
    positive("im", im)
    if failed.all() or not failed.any():
        return float("nan"), float("nan")
    p = _fit(jnp.log(jnp.asarray(im)), jnp.asarray(failed, dtype=float), steps)
    return float(jnp.exp(p[0])), float(jnp.exp(p[1]))


@eqx.filter_jit
def _fit(x, y, steps):
    """Adam on (ln median, ln beta) minimising the negative log-likelihood."""

    def nll(p):
        z = (x - p[0]) / jnp.exp(p[1])
        return -jnp.sum(y * norm.logcdf(z) + (1 - y) * norm.logcdf(-z))

    opt = optax.adam(0.05)
    p = jnp.array([jnp.mean(x), jnp.log(0.5)])

    def body(carry, _):
        p, state = carry
        updates, state = opt.update(jax.grad(nll)(p), state, p)
        return (optax.apply_updates(p, updates), state), None

    (p, _), _ = jax.lax.scan(body, (p, opt.init(p)), None, length=steps)
    return p


class Fragility(eqx.Module):
    """An ensemble's results: one row per motion.

    `im` is the intensity measure (`measure`: "pga" in m/s^2, "pgv" in m/s, or
    "pga_ratio" = PGA / (g tan alpha)); `rocked` and `overturned` per motion;
    lognormal fits (`median`, `beta`) of P(rocking) and P(overturning).
    """

    im: np.ndarray
    rocked: np.ndarray
    overturned: np.ndarray
    status: np.ndarray
    measure: str
    median_rocking: float
    beta_rocking: float
    median_overturning: float
    beta_overturning: float

    def probability(self, im, which: str = "overturning"):
        """The fitted lognormal P(rocking or overturning | IM)."""
        median = getattr(self, f"median_{which}")
        beta = getattr(self, f"beta_{which}")
        return np.asarray(norm.cdf(np.log(np.asarray(im) / median) / beta))


def fragility(
    slenderness: float,
    size: float,
    base: AbstractIsolator,
    motions: AbstractGroundMotion,
    *,
    measure: str = "pga",
    **map_options,
) -> Fragility:
    """Rocking and overturning of one block over an ensemble of motions.

    `motions` is an `MPPulse` whose parameters carry one batch axis (pulse
    parameters sampled or swept; e.g. a scaled Table 3.1 pulse,
    `MPPulse(scales * p.amplitude, p.frequency, p.gamma, p.phase)`). The
    analyses run as one behavior map with a motion axis; `map_options` go to
    `behavior_map`. Returns a `Fragility` with lognormal fits by maximum
    likelihood.
    """
    if measure not in MEASURES:
        raise ValueError(f"`measure` must be one of {MEASURES}, got {measure!r}")
    if not isinstance(motions, MPPulse):
        raise ValueError("`motions` must be an MPPulse with batched parameters")
    bm = behavior_map([slenderness], [size], base, motions, **map_options)
    outcome = bm.outcome.reshape(-1)
    pga, pgv = _peaks(motions)
    if not (np.all(pga > 0) and np.all(pgv > 0)):
        raise ValueError(
            "every motion of `motions` must move the ground (an intensity measure "
            f"> 0): {int(np.sum(~((pga > 0) & (pgv > 0))))} of them have zero "
            "amplitude"
        )
    pga = np.broadcast_to(pga, outcome.shape)
    pgv = np.broadcast_to(pgv, outcome.shape)
    im = {"pga": pga, "pgv": pgv, "pga_ratio": pga * slenderness / GRAVITY}[measure]
    ok = bm.status.reshape(-1) == Status.SUCCESS
    rocked = outcome != Outcome.NO_ROCKING
    overturned = outcome == Outcome.OVERTURNED
    med_r, beta_r = fit_lognormal(im[ok], rocked[ok])
    med_o, beta_o = fit_lognormal(im[ok], overturned[ok])
    return Fragility(
        im=np.asarray(im),
        rocked=rocked,
        overturned=overturned,
        status=bm.status.reshape(-1),
        measure=measure,
        median_rocking=med_r,
        beta_rocking=beta_r,
        median_overturning=med_o,
        beta_overturning=beta_o,
    )
