"""Fitting a Mavroeidis-Papageorgiou pulse to a recorded accelerogram."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from ._ground import MPPulse
from ._record import Record

_F_LOW, _F_HIGH = 0.1, 2.0  # range of the starting frequencies (Hz)
_GAMMA_MAX = 10.0  # gamma lies in (1, _GAMMA_MAX)
_GAMMA_START = 2.0
_MIN_SAMPLES = 100
_MIN_DURATION = 2.0  # s
_LEARNING_RATE = 0.05
_POLISH_STEPS = 30  # Levenberg-Marquardt steps on the best start
_COARSE_DT = 0.02  # s, the sampling of the velocity during the Adam stage


class PulseFit(eqx.Module):
    """A Mavroeidis-Papageorgiou pulse and how well it matches a record
    (`fit_pulse`, `score_pulse`).

    With the record's baseline-corrected velocity v_k and the pulse's velocity
    p_k = p(k dt) at its samples (m/s):

        correlation  = sum(v p) / sqrt(sum(v^2) sum(p^2))
        energy_share = max(0, 1 - sum((v - p)^2) / sum(v^2))

    Attributes:
        pulse: The `MPPulse` on the record's time axis (t0 in s from the
            record's first sample); as `fit_pulse` fits it, A > 0 m/s and nu
            in [0, 360) degrees.
        correlation: The normalized correlation of the two velocity histories
            (-), in [-1, 1].
        energy_share: The share of the record's velocity energy sum(v^2) that
            the pulse explains (-), in [0, 1].
    """

    pulse: MPPulse
    correlation: Float[Array, ""]
    energy_share: Float[Array, ""]


def _velocity(samples: np.ndarray, dt: float) -> np.ndarray:
    """Trapezoid-rule integral of samples at interval `dt` (s), from 0: the
    velocity (m/s) of accelerations (m/s^2), the displacement (m) of
    velocities."""
    steps = 0.5 * dt * (samples[1:] + samples[:-1])
    return np.concatenate([[0.0], np.cumsum(steps)])


def _detrended(x: np.ndarray) -> np.ndarray:
    """`x` less its least-squares line over the sample index."""
    k = np.arange(x.size, dtype=np.float64)
    design = np.stack([np.ones_like(k), k], axis=1)
    coef, *_ = np.linalg.lstsq(design, x, rcond=None)
    return x - design @ coef


def _unpack(theta, scale):
    """Pulse parameters (A, f_p, gamma, nu in radians, t0) from unconstrained
    ones: A / v_peak, log f_p, logit((gamma - 1) / (gamma_max - 1)), nu, t0."""
    a_hat, log_f, logit_g, nu, t0 = theta
    gamma = 1.0 + (_GAMMA_MAX - 1.0) * jax.nn.sigmoid(logit_g)
    return scale * a_hat, jnp.exp(log_f), gamma, nu, t0


def _pulse_velocity(theta, scale, t):
    amplitude, f, gamma, nu, t0 = _unpack(theta, scale)
    tau = t - t0
    w = 2.0 * jnp.pi * f
    inside = jnp.abs(tau) <= 0.5 * gamma / f
    # tau = 0 outside keeps the phase small (and the gradient finite).
    tau_in = jnp.where(inside, tau, 0.0)
    p = 0.5 * amplitude * (1.0 + jnp.cos(w * tau_in / gamma)) * jnp.cos(w * tau_in + nu)
    return jnp.where(inside, p, 0.0)


def _residual(theta, v, mask, basis, t, scale):
    """(u - p) / v_peak at the samples less its least-squares line (`basis`:
    orthonormal columns spanning 1 and t on the samples); zero on the padding."""
    r = mask * (v - _pulse_velocity(theta, scale, t)) / scale
    return r - basis @ (basis.T @ r)


def _samples(u: np.ndarray, dt: float, stride: int):
    """Every `stride`-th of the velocity samples `u` (m/s), zero-padded to a
    power of two, with their mask and times (s)."""
    u = u[::stride]
    size = max(128, 1 << (u.size - 1).bit_length())
    padded, mask = np.zeros(size), np.zeros(size)
    padded[: u.size], mask[: u.size] = u, 1.0
    return padded, mask, stride * dt * np.arange(size)


def _loss(theta, data):
    r = _residual(theta, *data)
    return jnp.sum(r * r)


def _data(v, mask, t, scale):
    basis = jnp.linalg.qr(jnp.stack([mask, mask * t], axis=1))[0]
    return v, mask, basis, t, scale


@eqx.filter_jit
def _fit(fine, coarse, scale, theta0, steps):
    """Adam from every start (vmapped) on the `coarse` samples, then
    Levenberg-Marquardt on the best, on the `fine` ones; the best parameters
    and their misfit. `fine`, `coarse`: (velocity, mask, times)."""
    fine, coarse = _data(*fine, scale), _data(*coarse, scale)

    def loss(theta):
        return _loss(theta, coarse)

    schedule = optax.cosine_decay_schedule(_LEARNING_RATE, steps, alpha=1e-3)
    optimizer = optax.adam(schedule)
    value_and_grad = jax.value_and_grad(loss)

    def descend(theta):
        def step(carry, _):
            theta, state = carry
            _, grad = value_and_grad(theta)
            updates, state = optimizer.update(grad, state, theta)
            return (optax.apply_updates(theta, updates), state), None

        (theta, _), _ = jax.lax.scan(
            step, (theta, optimizer.init(theta)), None, length=steps
        )
        return theta, loss(theta)

    thetas, losses = jax.vmap(descend)(theta0)
    losses = jnp.where(jnp.isfinite(losses), losses, jnp.inf)
    best = thetas[jnp.argmin(losses)]

    def fine_loss(theta):
        return _loss(theta, fine)

    jacobian = jax.jacfwd(lambda th: _residual(th, *fine))

    def polish(carry, _):
        theta, damping = carry
        r = _residual(theta, *fine)
        jac = jacobian(theta)
        jtj = jac.T @ jac
        lhs = jtj + damping * jnp.diag(jnp.diag(jtj) + 1e-12)
        trial = theta - jnp.linalg.solve(lhs, jac.T @ r)
        better = fine_loss(trial) < jnp.sum(r * r)
        theta = jnp.where(better, trial, theta)
        damping = jnp.where(better, damping / 3.0, damping * 4.0)
        return (theta, damping), None

    (best, _), _ = jax.lax.scan(
        polish, (best, jnp.asarray(1e-3)), None, length=_POLISH_STEPS
    )
    return best, fine_loss(best)


def _starts(count: int, t_peak: float) -> np.ndarray:
    """`count` starting points: a grid of f_p (log-spaced over 0.1-2 Hz) by
    nu (0-360 degrees), A = v_peak, gamma = 2, t0 at the peak |velocity|."""
    n_f = math.ceil(math.sqrt(count))
    n_nu = math.ceil(count / n_f)
    i = np.arange(count)
    freq = np.geomspace(_F_LOW, _F_HIGH, n_f)[i % n_f]
    nu = 2.0 * np.pi * (i // n_f) / n_nu
    u = (_GAMMA_START - 1.0) / (_GAMMA_MAX - 1.0)
    return np.stack(
        [
            np.ones(count),
            np.log(freq),
            np.full(count, np.log(u / (1.0 - u))),
            nu,
            np.full(count, t_peak),
        ],
        axis=1,
    )


def _checked(
    record, verb: str, min_samples: int = 2, min_duration: float = 0.0
) -> tuple[np.ndarray, float]:
    """The samples (m/s^2) and time step (s) of one finite record, not all
    zeros, of at least `min_samples` samples over `min_duration` (s); else
    ValueError."""
    if not isinstance(record, Record):
        raise ValueError(f"`record` must be a Record, got {type(record).__name__}")
    if record.batch_shape != ():
        raise ValueError(
            f"`record` must be one record, not a suite of shape "
            f"{record.batch_shape}: {verb} one record at a time (`.select(i)`)"
        )
    dt = float(record.dt)
    samples = np.asarray(record.samples, dtype=np.float64)[: int(record.length)]
    if not np.all(np.isfinite(samples)):
        raise ValueError("`record` has samples that are not finite (NaN or inf)")
    n = samples.size
    if n < min_samples or (n - 1) * dt < min_duration:
        raise ValueError(
            f"`record` is too short to {verb} a pulse: {n} samples over "
            f"{(n - 1) * dt:g} s (need >= {min_samples} samples and "
            f">= {min_duration:g} s)"
        )
    if not np.any(samples):
        raise ValueError("`record` is all zeros: there is no pulse to find")
    return samples, dt


def fit_pulse(record: Record, *, starts: int = 64, steps: int = 400) -> PulseFit:
    """Fit a Mavroeidis-Papageorgiou pulse to a record's velocity history.

    The record's acceleration a_k (m/s^2, sample k at t_k = k dt) is
    integrated to velocity with the trapezoid rule,
    u_k = sum_{j<k} dt (a_j + a_{j+1}) / 2 (m/s), and a linear baseline
    c0 + c1 t is removed from it: v_k = u_k - c0 - c1 t_k. The pulse
    (see `MPPulse`)

        p(t) = A/2 [1 + cos(2 pi f_p (t - t0) / gamma)] cos(2 pi f_p (t - t0) + nu)

    for |t - t0| <= gamma / (2 f_p), zero elsewhere, is fitted by minimizing
    the misfit sum_k (v_k - p(t_k))^2 over (A, f_p, gamma, nu, t0) and the
    baseline: the line is the least-squares line fitted to the velocity less
    the pulse, u - p (fitted jointly with the pulse, so a pulse whose
    displacement does not return to zero is not distorted by the baseline;
    the starting points use the line fitted to u itself).

    The misfit is multimodal in f_p and nu, so Adam (Optax, gradients by JAX)
    runs from `starts` starting points at once (vmapped, one compiled call):
    f_p log-spaced over 0.1-2 Hz times nu over 0-360 degrees, with gamma = 2,
    A = max |v| and t0 at the time of max |v|. The unconstrained parameters
    are A / max|v|, log f_p (so f_p > 0), logit((gamma - 1) / 9) (so
    1 < gamma < 10), nu (radians) and t0 (s). Adam reads the velocity every
    0.02 s (every sample of a coarser record); 30 Levenberg-Marquardt steps
    on every sample then refine the best start. The compiled function is
    shared by every record whose lengths round up to the same powers of two.

    Args:
        record: One accelerogram (not a suite), finite, at least 100 samples
            and 2 s long, not all zeros.
        starts: The number of starting points (>= 1).
        steps: The Adam steps per start (>= 1).

    Returns:
        A `PulseFit`: the fitted pulse (A > 0 m/s, nu in [0, 360) degrees,
        t0 in s from the record's first sample), the correlation of the
        record's and the pulse's velocities, and the share of the record's
        velocity energy sum(v^2) that the pulse explains.

    Raises:
        ValueError: if `record` is not a single `Record`, has a sample that
            is not finite, is shorter than 100 samples or 2 s, or is all
            zeros; if `starts` or `steps` is not a positive integer (the
            message names the parameter); or, after the fit, if the record
            is shorter than the fitted pulse's period 1/f_p (it does not
            hold a whole cycle, so the pulse is not determined; a velocity
            that drifts far beyond the pulse, from a trend in the
            acceleration, gives such a fit too).

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> pulse = jr.MPPulse(0.8, 0.6, 2.0, 60.0, t0=5.0)
        >>> t = np.arange(0.0, 12.0, 0.005)
        >>> rec = jr.Record(np.asarray(pulse.acceleration(t)), 0.005)
        >>> fit = jr.fit_pulse(rec)
        >>> round(float(fit.pulse.frequency), 4), round(float(fit.pulse.phase), 2)
        (0.6, 60.0)
        >>> bool(fit.correlation > 0.999)
        True
    """
    for name, value in (("starts", starts), ("steps", steps)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"`{name}` must be a positive integer, got {value!r}")
        if value < 1:
            raise ValueError(f"`{name}` must be a positive integer, got {value!r}")
    samples, dt = _checked(record, "fit", _MIN_SAMPLES, _MIN_DURATION)
    u, theta, scale = _fitted_parameters(samples, dt, int(starts), int(steps))
    pulse = _pulse_of(theta, scale, duration=(samples.size - 1) * dt)
    return _scored(u, dt, pulse)


def _fitted_parameters(samples, dt, starts: int, steps: int):
    """The record's velocity u (m/s), the best fit's unconstrained
    parameters, and the velocity's scale max |v| (see `fit_pulse`)."""
    u = _velocity(samples, dt)
    v = _detrended(u)  # for the starting points only
    peak = int(np.argmax(np.abs(v)))
    scale = float(np.abs(v[peak]))
    stride = max(1, int(_COARSE_DT / dt + 1e-9))
    fine, coarse = _samples(u, dt, 1), _samples(u, dt, stride)
    theta, _ = _fit(
        tuple(jnp.asarray(x) for x in fine),
        tuple(jnp.asarray(x) for x in coarse),
        jnp.asarray(scale),
        jnp.asarray(_starts(starts, peak * dt)),
        steps,
    )
    return u, np.asarray(theta), scale


def _pulse_of(theta, scale: float, duration: float) -> MPPulse:
    """The `MPPulse` of the fitted parameters, A > 0 and nu in [0, 360);
    `ValueError` if a record of `duration` s holds no whole period of it."""
    amplitude, f, gamma, nu, t0 = (float(x) for x in _unpack(theta, scale))
    # A fit at the bound gamma -> 1 rounds to 1.0, which `MPPulse` refuses.
    gamma = max(gamma, math.nextafter(1.0, 2.0))
    nu = math.degrees(nu)
    if amplitude < 0.0:  # -A cos(x + nu) = A cos(x + nu + 180 deg)
        amplitude, nu = -amplitude, nu + 180.0
    if not 1.0 / f <= duration:
        raise ValueError(
            f"`record` lasts {duration:g} s, less than the period 1/f_p = "
            f"{1.0 / f:.3g} s of the pulse fitted to it: the record does not hold "
            "a whole cycle of its pulse, so the pulse is not determined; fit a "
            "longer record, or, if the record's velocity drifts (a trend in its "
            "acceleration, which the fit's linear baseline does not remove), "
            "correct its baseline first"
        )
    return MPPulse(amplitude, f, gamma, nu % 360.0, t0=t0)


def score_pulse(record: Record, pulse: MPPulse) -> PulseFit:
    """How well a given pulse matches a record's velocity, as `fit_pulse`
    measures its fits.

    With u_k the record's trapezoid-rule velocity (m/s) at t_k = k dt and
    p_k = p(t_k) the pulse's velocity (m/s), the record's velocity is
    v_k = u_k - c0 - c1 t_k with c0 + c1 t the least-squares line fitted to
    u - p (the baseline `fit_pulse` fits jointly with the pulse), and

        correlation  = sum(v p) / sqrt(sum(v^2) sum(p^2))
        energy_share = max(0, 1 - sum((v - p)^2) / sum(v^2))

    The pulse's t0 is in s from the record's first sample. A pulse that
    misses the record (p = 0 at every sample) has correlation 0.

    Args:
        record: One accelerogram (not a suite), finite, not all zeros (m/s^2).
        pulse: One `MPPulse` (no batch axes).

    Returns:
        A `PulseFit` holding `pulse`, its correlation and its energy share.

    Raises:
        ValueError: if `record` is not a single finite `Record` or is all
            zeros, or if `pulse` is not a single `MPPulse`.

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> pulse = jr.MPPulse(0.8, 0.6, 2.0, 60.0, t0=5.0)
        >>> t = np.arange(0.0, 12.0, 0.005)
        >>> rec = jr.Record(np.asarray(pulse.acceleration(t)), 0.005)
        >>> round(float(jr.score_pulse(rec, pulse).correlation), 6)
        1.0
        >>> reversed_pulse = jr.MPPulse(0.8, 0.6, 2.0, 240.0, t0=5.0)
        >>> round(float(jr.score_pulse(rec, reversed_pulse).correlation), 3)
        -1.0
    """
    samples, dt = _checked(record, "score")
    if not isinstance(pulse, MPPulse):
        raise ValueError(f"`pulse` must be an MPPulse, got {type(pulse).__name__}")
    if pulse.batch_shape != ():
        raise ValueError(
            f"`pulse` must be one pulse, not a batch of shape {pulse.batch_shape}"
        )
    return _scored(_velocity(samples, dt), dt, pulse)


def _histories(record: Record, pulse: MPPulse) -> dict[str, np.ndarray]:
    """The record's and the pulse's acceleration (m/s^2), velocity (m/s) and
    displacement (m) at the record's sample times `t` (s): the record's
    velocity as `score_pulse` corrects it, the displacements integrated from
    zero with the trapezoid rule."""
    samples, dt = _checked(record, "plot")
    v, p = _corrected(_velocity(samples, dt), dt, pulse)
    t = dt * np.arange(samples.size)
    return dict(
        t=t,
        record_acceleration=samples,
        pulse_acceleration=np.asarray(pulse.acceleration(jnp.asarray(t))),
        record_velocity=v,
        pulse_velocity=p,
        record_displacement=_velocity(v, dt),
        pulse_displacement=_velocity(p, dt),
    )


def _corrected(u: np.ndarray, dt: float, pulse: MPPulse):
    """The velocity samples `u` (m/s) less the least-squares line fitted to
    u - p, and the pulse's velocity p (m/s) at the same times."""
    p = np.asarray(pulse.velocity(jnp.asarray(dt * np.arange(u.size))))
    return _detrended(u - p) + p, p


def _scored(u: np.ndarray, dt: float, pulse: MPPulse) -> PulseFit:
    v, p = _corrected(u, dt, pulse)
    energy = float(np.sum(v * v))
    norm = math.sqrt(energy * float(np.sum(p * p)))
    correlation = float(np.sum(v * p)) / norm if norm > 0.0 else 0.0
    share = max(0.0, 1.0 - float(np.sum((v - p) ** 2)) / energy)
    return PulseFit(
        pulse=pulse,
        correlation=jnp.asarray(correlation),
        energy_share=jnp.asarray(share),
    )
