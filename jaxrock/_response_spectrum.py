"""Elastic response spectra of linear oscillators under any ground motion,
exact for a record's piecewise-linear samples (Nigam & Jennings 1969)."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._ground import AbstractGroundMotion
from ._misc import check, grid_axis
from ._record import Record, component, is_vertical

# A closed-form pulse is sampled every min(_PULSE_STEP, its `max_step` /
# _PULSE_SUBSTEPS) s (and, for a spectrum, at most the shortest period /
# _PULSE_POINTS): with `max_step` 1/32 of its cycle, 800 samples a cycle keep
# its piecewise-linear interpolant within (2 pi / 800)^2 / 8 < 1e-5 of its
# amplitude, whatever its frequency.
_PULSE_STEP = 1e-3
_PULSE_SUBSTEPS = 25
_PULSE_POINTS = 50
# Gauss-Legendre nodes per panel of the input coefficients' integrals, and the
# largest omega h of a panel: the integrands are entire, and 16 nodes over
# omega h <= 1 integrate them to rounding.
_NODES = 16
_PANEL = 1.0
# The periods of a spectrum (s): from 1 ms (far stiffer than any structure or
# object: the oscillator follows the ground, Sa = PGA) to 100 s (longer than
# any isolated structure's). Shorter ones need omega h / _PANEL quadrature
# panels per record step (memory).
PERIOD_RANGE = (1e-3, 100.0)


class MotionSamples(eqx.Module):
    """A motion's batch as rows of samples, piecewise linear between them.

    `rows[r]` holds x_g'' (m/s^2) every `dt[r]` s, its first `length[r]`
    samples meaningful. A scaled record keeps its unscaled rows and a factor
    per member of the batch: member i reads row `row[i]` times `factor[i]`.
    """

    rows: np.ndarray
    dt: np.ndarray
    length: np.ndarray
    row: np.ndarray
    factor: np.ndarray
    batch_shape: tuple = eqx.field(static=True)

    def per_member(self, values, power: int = 1):
        """Values of the rows (leading axis) for each member, times its
        factor to `power` (1 for quantities linear in x_g''), shaped
        (*batch_shape, ...)."""
        values = np.asarray(values)
        factor = self.factor.reshape((-1,) + (1,) * (values.ndim - 1)) ** power
        out = factor * values[self.row]
        return out.reshape(self.batch_shape + values.shape[1:])

    def of_member(self, values):
        """Values of the rows for each member, not scaled (e.g. durations)."""
        values = np.asarray(values)[self.row]
        return values.reshape(self.batch_shape + values.shape[1:])


def motion_samples(motion: AbstractGroundMotion, step=None, tail=0.0):
    """The samples of `motion` (`MotionSamples`): a record's own (a suite's
    rows, each scaled member reading its row times its factor); a closed-form
    pulse's on a grid of min(`step` (default `_PULSE_STEP`), its `max_step`
    / `_PULSE_SUBSTEPS`) s from t = 0 to its end plus `tail` s, where it is
    zero."""
    if not isinstance(motion, AbstractGroundMotion):
        raise ValueError(
            f"`motion` must be a ground motion (a Record or a pulse), got "
            f"{type(motion).__name__}"
        )
    batch = tuple(motion.batch_shape)
    if isinstance(motion, Record):
        n = motion.sample_count
        rows = np.asarray(motion.unscaled).reshape(-1, n)
        count = rows.shape[0]
        members = int(np.prod(batch))

        def per_row(x):  # the factors' axes lead the batch
            return np.reshape(np.broadcast_to(np.asarray(x), batch), (-1, count))[0]

        factor = np.ones(members)
        if motion.factor is not None:
            factor = np.reshape(np.asarray(motion.factor), -1)
        return MotionSamples(
            rows=rows,
            dt=per_row(motion.dt).astype(float),
            length=per_row(motion.length).astype(int),
            row=np.arange(members) % count,
            factor=factor,
            batch_shape=batch,
        )
    flat = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, batch).reshape(-1), motion
    )
    end = np.reshape(np.asarray(flat.end_time), -1) + tail
    limit = flat.max_step  # None: a motion without a step limit
    own = np.inf if limit is None else np.reshape(limit, -1) / _PULSE_SUBSTEPS
    step = np.minimum(_PULSE_STEP if step is None else float(step), own)
    step = np.broadcast_to(step, end.shape)
    length = np.floor(end / step).astype(int) + 2
    index = jnp.arange(int(length.max()))
    rows = np.asarray(
        jax.vmap(lambda m, h: m.acceleration(h * index))(flat, jnp.asarray(step))
    )
    members = rows.shape[0]
    return MotionSamples(
        rows=rows,
        dt=step.astype(float),
        length=length,
        row=np.arange(members),
        factor=np.ones(members),
        batch_shape=batch,
    )


def oscillator_coefficients(period, damping, dt):
    """The exact one-step map of u'' + 2 zeta omega u' + omega^2 u = -x_g''
    over a step h = `dt` with x_g'' linear from a0 to a1 (Nigam & Jennings
    1969): (u, u')_1 = A (u, u')_0 + B0 a0 + B1 a1. Returns the eight
    coefficients (A11, A12, A21, A22, B0u, B1u, B0v, B1v), each of the shape
    of `period` (s).

    A is the matrix exponential in closed form; B0 and B1 are the integrals
    of the impulse response g(tau) times tau / h and 1 - tau / h over
    [0, h], by Gauss-Legendre quadrature: the closed forms of Nigam &
    Jennings subtract terms of order 2 zeta / (omega^3 h) to leave one of
    order h^2, and lose (T / h)^3 ulps (1e-4 at T = 100 s, h = 1 ms)."""
    omega = 2 * np.pi / np.asarray(period, dtype=float)
    h = float(dt)
    wd = omega * np.sqrt(1.0 - damping**2)

    def impulse(tau):  # (u, u') at tau after a unit impulse of x_g''
        decay = np.exp(-damping * omega * tau)
        sin_over = tau * np.sinc(wd * tau / np.pi)  # sin(wd tau) / wd
        u = -decay * sin_over
        v = -decay * (np.cos(wd * tau) - damping * omega * sin_over)
        return u, v, decay, sin_over

    u, v, decay, sin_over = impulse(h)
    cos = np.cos(wd * h)
    a11 = decay * (cos + damping * omega * sin_over)
    a12 = decay * sin_over
    a21 = -(omega**2) * decay * sin_over
    a22 = decay * (cos - damping * omega * sin_over)

    panels = max(1, int(np.ceil(np.max(omega) * h / _PANEL)))
    x, w = np.polynomial.legendre.leggauss(_NODES)
    edges = np.linspace(0.0, h, panels + 1)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    tau = (mid[:, None] + half[:, None] * x).reshape(-1)
    weight = (half[:, None] * w).reshape(-1)
    gu, gv, _, _ = impulse(tau[:, None] + 0.0 * omega)  # (nodes, periods)
    rise = (weight * tau / h)[:, None]
    fall = (weight * (1.0 - tau / h))[:, None]
    # From a0 (weight 1 - s / h at s = h - tau) and a1 (weight s / h).
    b0u, b1u = np.sum(gu * rise, 0), np.sum(gu * fall, 0)
    b0v, b1v = np.sum(gv * rise, 0), np.sum(gv * fall, 0)
    return np.stack([a11, a12, a21, a22, b0u, b1u, b0v, b1v])


@functools.partial(jax.jit, static_argnames="free")
def _peak_displacements(rows, length, coefficients, omega, damping, free=False):
    """max |u| over the samples k < length of each row (R, n) and period:
    the recurrence of `oscillator_coefficients` (8, R, P) from rest; with
    `free`, also over the free vibration after each row's last sample
    (`_free_vibration_peak`: the ground still from there on)."""
    a11, a12, a21, a22, b0u, b1u, b0v, b1v = coefficients
    zero = jnp.zeros(a11.shape)

    def step(carry, x):
        u, v, peak, end = carry
        a0, a1, k = x
        a0, a1 = a0[:, None], a1[:, None]
        u, v = (
            a11 * u + a12 * v + b0u * a0 + b1u * a1,
            a21 * u + a22 * v + b0v * a0 + b1v * a1,
        )
        inside = (k + 1 < length)[:, None]
        if free:  # (u, v) at the row's last sample
            last = (k + 2 == length)[:, None]
            end = tuple(jnp.where(last, new, old) for new, old in zip((u, v), end))
        peak = jnp.where(inside, jnp.maximum(peak, jnp.abs(u)), peak)
        return (u, v, peak, end), None

    ks = jnp.arange(rows.shape[1] - 1)
    (_, _, peak, end), _ = jax.lax.scan(
        step, (zero, zero, zero, (zero, zero)), (rows[:, :-1].T, rows[:, 1:].T, ks)
    )
    if not free:
        return peak
    return jnp.maximum(peak, _free_vibration_peak(*end, omega, damping))


def _free_vibration_peak(u, v, omega, damping):
    """max |u(tau)| over tau >= 0 of the free vibration u'' + 2 zeta omega u'
    + omega^2 u = 0 from (u, v) (m, m/s): its extrema decay, so the peak is
    |u| at tau = 0 or at the first extremum, u'(tau_1) = 0 with omega_d tau_1
    in [0, pi): u' = e^(-zeta omega tau) (v cos omega_d tau - K sin omega_d
    tau), K = (omega^2 u + zeta omega v) / omega_d."""
    wd = omega * jnp.sqrt(1.0 - damping**2)
    k = (omega**2 * u + damping * omega * v) / wd
    x = jnp.mod(jnp.arctan2(v, k), jnp.pi)  # omega_d tau_1
    b = (v + damping * omega * u) / wd
    at = jnp.exp(-damping * omega * x / wd) * (u * jnp.cos(x) + b * jnp.sin(x))
    return jnp.maximum(jnp.abs(u), jnp.abs(at))


def spectral_displacements(samples: MotionSamples, periods, damping, free=False):
    """max |u| (m) of the rows of `samples` at `periods` (R, P), unscaled:
    every row's coefficients from its own dt, all rows in one compiled call;
    with `free`, the free vibration after each row's last sample counts."""
    coefficients = np.stack(
        [oscillator_coefficients(periods, damping, dt) for dt in samples.dt], axis=1
    )
    return np.asarray(
        _peak_displacements(
            jnp.asarray(samples.rows),
            jnp.asarray(samples.length),
            jnp.asarray(coefficients),
            jnp.asarray(2 * np.pi / np.asarray(periods, dtype=float)),
            float(damping),
            free=free,
        )
    )


def period_in_range(period) -> bool:
    """Whether one period (s) is finite and in `PERIOD_RANGE`."""
    low, high = PERIOD_RANGE
    return bool(np.isfinite(period) and low <= period <= high)


def check_periods(periods, name: str = "periods") -> np.ndarray:
    """`periods` as a 1-D float array of finite values in `PERIOD_RANGE`
    (`ValueError` naming `name`)."""
    periods = grid_axis(name, periods)
    low, high = PERIOD_RANGE
    check(name, periods, lambda v: (v >= low) & (v <= high), f"in [{low}, {high}] s")
    return periods


def check_damping(damping) -> float:
    """`damping` as a float in [0, 1) (`ValueError`)."""
    value = np.asarray(damping, dtype=float) if _real(damping) else None
    if value is None or value.ndim:
        raise ValueError(f"`damping` must be one number >= 0 and < 1, got {damping!r}")
    check("damping", value, lambda d: (d >= 0) & (d < 1), ">= 0 and < 1")
    return float(value)


def _real(x) -> bool:
    try:
        return np.asarray(x).dtype.kind in "fiu" and not isinstance(x, bool)
    except (TypeError, ValueError):
        return False


class ResponseSpectrum(eqx.Module):
    """Elastic response spectra of a motion or of each motion of a batch.

    For each period T (omega = 2 pi / T) and the damping ratio zeta, the
    relative displacement u of u'' + 2 zeta omega u' + omega^2 u = -x_g''
    from rest gives the spectral displacement SD = max |u| (m), the
    pseudo-spectral velocity PSV = omega SD (m/s) and the pseudo-spectral
    acceleration PSA = omega^2 SD (m/s^2).

    Attributes:
        periods: the oscillator periods T (s), shape (P,).
        damping: the damping ratio zeta (-).
        displacement: SD (m), shape (*batch, P).
        pseudo_velocity: PSV (m/s), shape (*batch, P).
        pseudo_acceleration: PSA (m/s^2), shape (*batch, P).
        names: the records' names of a suite (or of one record); None otherwise.
    """

    periods: np.ndarray
    damping: float
    displacement: np.ndarray
    pseudo_velocity: np.ndarray
    pseudo_acceleration: np.ndarray
    names: tuple | None = None


def response_spectrum(
    motion: AbstractGroundMotion, periods, damping: float = 0.05
) -> ResponseSpectrum:
    """The displacement, pseudo-velocity and pseudo-acceleration spectra of
    a ground motion, or of each motion of a suite or batch.

    A record's x_g'' is linear between its samples, and the oscillator's
    state is carried from sample to sample by the exact solution over each
    interval (Nigam & Jennings 1969); the peak is taken over the record's
    samples, from t = 0 to its last sample. A closed-form pulse is sampled
    every min(1 ms, T_min / 50) s from t = 0 to its end and treated as a
    record, and the oscillator's free vibration after it counts, in closed
    form (its first extremum: later ones decay). A suite's
    records, of any lengths and time steps, and all periods run in one
    compiled call; each record's spectrum equals, to the bit, that of the
    record alone. A scaled record's spectra are those of its samples before
    scaling times its factor.

    Args:
        motion: a `Record`, a suite (`Record.stack`), a scaled record or
            suite, or a pulse (`MPPulse`, `SinePulse`, batched or not).
        periods: the oscillator periods T (s), in [0.001, 100] s; a number or
            a 1-D array.
        damping: the damping ratio zeta, >= 0 and < 1; default 0.05.

    Returns:
        A `ResponseSpectrum` with arrays of shape (*motion.batch_shape, P).

    Raises:
        ValueError: periods outside [0.001, 100] s, a damping outside [0, 1), or
            a `motion` that is not a ground motion (checked before any
            compile).

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> t = np.arange(0.0, 20.0, 0.01)
        >>> rec = jr.Record(np.sin(2 * np.pi * t), 0.01)  # 1 m/s^2 at 1 Hz
        >>> s = jr.response_spectrum(rec, [0.1, 1.0, 10.0], damping=0.05)
        >>> s.pseudo_acceleration.round(2)  # resonance at T = 1 s: near 1 / (2 zeta)
        array([1.04, 9.98, 0.1 ])
    """
    periods = check_periods(periods)
    damping = check_damping(damping)
    step = min(_PULSE_STEP, float(periods.min()) / _PULSE_POINTS)
    samples = motion_samples(motion, step=step)
    free = not isinstance(motion, Record)  # a pulse: its free vibration counts
    peak = samples.per_member(spectral_displacements(samples, periods, damping, free))
    omega = 2 * np.pi / periods
    names = motion.names() if isinstance(motion, Record) else None
    return ResponseSpectrum(
        periods=periods,
        damping=damping,
        displacement=peak,
        pseudo_velocity=omega * peak,
        pseudo_acceleration=omega**2 * peak,
        names=names,
    )


# RotD spectra rotate the pair of components in steps of this many degrees
# over [0, 180) (Boore 2010): 180 azimuths.
_ROTD_STEP = 1.0


@jax.jit
def _rotated_peaks(starts, rows, coefficients, cos, sin):
    """max |u1 cos(a) + u2 sin(a)| over the samples of the two rows (2, n),
    x_g'' linear from `starts` (just after each sample) to `rows` (at the
    next), for each period and azimuth a (P, A): the oscillator is linear,
    so the response to the rotated motion is the same rotation of the
    components' responses."""
    a11, a12, a21, a22, b0u, b1u, b0v, b1v = coefficients
    zero = jnp.zeros((2,) + a11.shape)

    def step(carry, x):
        u, v, peak = carry
        a0, a1 = x[0][:, None], x[1][:, None]
        u, v = (
            a11 * u + a12 * v + b0u * a0 + b1u * a1,
            a21 * u + a22 * v + b0v * a0 + b1v * a1,
        )
        rotated = u[0][:, None] * cos + u[1][:, None] * sin
        return (u, v, jnp.maximum(peak, jnp.abs(rotated))), None

    start = (zero, zero, jnp.zeros(a11.shape + cos.shape))
    (_, _, peak), _ = jax.lax.scan(step, start, (starts[:, :-1].T, rows[:, 1:].T))
    return peak


# Two components' azimuths may differ from perpendicular by this much (deg).
_SKEW = 1.0


def _check_horizontal_pair(first: Record, second: Record) -> None:
    """`ValueError` unless the components are horizontal (no vertical one by
    name) and, where both azimuths are known, perpendicular within `_SKEW`
    degrees: the rotation x_g'' = a1 cos a + a2 sin a holds for such axes."""
    for name, record in (("first", first), ("second", second)):
        if is_vertical(record):
            raise ValueError(
                f"`{name}` must be a horizontal component, got the vertical "
                f"component {component(record)} ({record.name})"
            )
    if first.azimuth is None or second.azimuth is None:
        return
    skew = abs((float(second.azimuth) - float(first.azimuth)) % 180.0 - 90.0)
    if skew > _SKEW:
        raise ValueError(
            "`first` and `second` must be perpendicular components (azimuths "
            f"90 deg apart, within {_SKEW:g} deg), got azimuths "
            f"{first.azimuth:g} and {second.azimuth:g} deg"
        )


def rotd50(
    first: Record, second: Record, periods, damping: float = 0.05
) -> ResponseSpectrum:
    """The RotD50 spectra of two horizontal components of one recording.

    For each period the two components are rotated to every azimuth a from
    0 to 179 degrees in steps of 1 (x_g'' = a1 cos a + a2 sin a), the peak
    response to each taken, and RotD50 is the median over the azimuths
    (Boore 2010). The oscillator is linear, so the response at each azimuth
    is the same rotation of the two components' exact responses (Nigam &
    Jennings, as `response_spectrum`), all in one compiled call. A component
    shorter than the other is zero just after its last sample.

    Args:
        first, second: the two horizontal components (`Record`s, not
            batched, of one time step, perpendicular where their azimuths
            are known; scaled records allowed).
        periods: the oscillator periods T (s), in [0.001, 100] s.
        damping: the damping ratio zeta, >= 0 and < 1; default 0.05.

    Returns:
        A `ResponseSpectrum` of shape (P,): RotD50 of SD, and PSV and PSA
        from it (the median commutes with the factors omega and omega^2).

    Raises:
        ValueError: components that are not single records of one time
            step, a vertical component (by name: UP, DWN, ...), two whose
            azimuths are known and not perpendicular (within 1 degree),
            periods outside [0.001, 100] s, or a damping outside [0, 1)
            (before any compile).

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> t = np.arange(0.0, 20.0, 0.01)
        >>> ns = jr.Record(np.sin(2 * np.pi * t), 0.01)  # 1 m/s^2 at 1 Hz
        >>> ew = jr.Record(0.5 * np.sin(2 * np.pi * t), 0.01)
        >>> both = jr.rotd50(ns, ew, [1.0])  # in phase: peaks of |cos a + sin a / 2|
        >>> one = jr.response_spectrum(ns, [1.0]).pseudo_acceleration
        >>> a = np.radians(np.arange(180.0))
        >>> round(float(both.pseudo_acceleration[0] / one[0]), 6)
        0.790547
        >>> round(float(np.median(np.abs(np.cos(a) + 0.5 * np.sin(a)))), 6)
        0.790547
    """
    for name, record in (("first", first), ("second", second)):
        if not isinstance(record, Record) or record.batch_shape != ():
            raise ValueError(
                f"`{name}` must be one record (a Record, not a suite), got "
                f"{type(record).__name__}"
                + (
                    f" of shape {record.batch_shape}"
                    if isinstance(record, Record)
                    else ""
                )
            )
    if float(first.dt) != float(second.dt):
        raise ValueError(
            "`second` must have the time step of `first` (two components of one "
            f"recording), got {float(second.dt)} s and {float(first.dt)} s"
        )
    _check_horizontal_pair(first, second)
    periods = check_periods(periods)
    damping = check_damping(damping)
    components = []
    for record in (first, second):
        samples = motion_samples(record)
        row = samples.per_member(samples.rows)
        components.append(np.asarray(row)[: int(samples.length[0])])
    n = max(c.size for c in components)
    rows = np.stack([np.pad(c, (0, n - c.size)) for c in components])
    # The shorter component is zero just after its last sample (a step).
    starts = rows.copy()
    starts[[0, 1], [c.size - 1 for c in components]] = 0.0
    azimuth = np.radians(np.arange(0.0, 180.0, _ROTD_STEP))
    coefficients = oscillator_coefficients(periods, damping, float(first.dt))
    peaks = _rotated_peaks(
        jnp.asarray(starts),
        jnp.asarray(rows),
        jnp.asarray(coefficients),
        jnp.asarray(np.cos(azimuth)),
        jnp.asarray(np.sin(azimuth)),
    )
    displacement = np.median(np.asarray(peaks), axis=-1)
    omega = 2 * np.pi / periods
    return ResponseSpectrum(
        periods=periods,
        damping=damping,
        displacement=displacement,
        pseudo_velocity=omega * displacement,
        pseudo_acceleration=omega**2 * displacement,
        names=("RotD50",),
    )
