"""Intensity measures of ground motions: peaks, Sa(T), Arias intensity, CAV,
significant duration and the dimensionless measures of rocking blocks."""

import re

import jax
import jax.numpy as jnp
import numpy as np

from ._ground import AbstractGroundMotion, MPPulse, SinePulse
from ._misc import GRAVITY, flag, positive
from ._record import Record
from ._response_spectrum import (
    check_periods,
    motion_samples,
    period_in_range,
    response_spectrum,
)
from ._vertical import WithVertical

# The measures by name; "sa:T" is Sa(T) at 5% damping, T in s.
MEASURES = (
    "pga",
    "pgv",
    "pgd",
    "sa:T",
    "arias",
    "cav",
    "d5_95",
    "tp",
    "pga_ratio",
    "pgv_ratio",
    "frequency_ratio",
)
# Sa's period in "sa:T": a decimal number, as "1", "0.75", ".5" or "2e-1".
_PERIOD = re.compile(r"(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
# Those of a block (the block's slenderness and size enter them).
BLOCK_MEASURES = ("pga_ratio", "pgv_ratio", "frequency_ratio")
# Each measure's meaning and unit (Sa's from `measure_attrs`).
_ATTRS = {
    "pga": {"long_name": "peak ground acceleration", "units": "m/s^2"},
    "pgv": {"long_name": "peak ground velocity", "units": "m/s"},
    "pgd": {"long_name": "peak ground displacement", "units": "m"},
    "arias": {"long_name": "Arias intensity", "units": "m/s"},
    "cav": {"long_name": "cumulative absolute velocity", "units": "m/s"},
    "d5_95": {"long_name": "significant duration D5-95", "units": "s"},
    "tp": {"long_name": "pulse period T_p", "units": "s"},
    "pga_ratio": {"long_name": "PGA / (g tan alpha)", "units": "1"},
    "pgv_ratio": {"long_name": "PGV p / (g tan alpha)", "units": "1"},
    "frequency_ratio": {"long_name": "omega_p / p", "units": "1"},
}
# Damping ratio of Sa(T).
SA_DAMPING = 0.05
# A closed-form pulse's peaks are read on this many points over its duration.
_PULSE_POINTS = 20001


def parse_measure(measure) -> tuple[str, float | None]:
    """(name, period): "sa:1.0" -> ("sa", 1.0); other names -> (name, None).
    `ValueError` naming `measure` for anything else."""
    allowed = (
        f"`measure` must be one of {', '.join(m for m in MEASURES if m != 'sa:T')} "
        "or 'sa:T' (Sa at period T s, in [0.001, 100])"
    )
    if not isinstance(measure, str):
        raise ValueError(f"{allowed}, got {measure!r}")
    if measure.startswith("sa:"):
        # A decimal number only (`float` also reads "1_0", " 1" and "inf").
        if not _PERIOD.fullmatch(measure[3:]) or not period_in_range(
            period := float(measure[3:])
        ):
            raise ValueError(f"{allowed}, got {measure!r}")
        return "sa", period
    if measure not in _ATTRS:
        raise ValueError(f"{allowed}, got {measure!r}")
    return measure, None


def measure_attrs(measure: str) -> dict:
    """The long name and unit of a measure (xarray attributes)."""
    name, period = parse_measure(measure)
    if name == "sa":
        return {
            "long_name": f"Sa({period:g} s), {SA_DAMPING:.0%} damping",
            "units": "m/s^2",
        }
    return dict(_ATTRS[name])


def _pulse_peaks(motion: AbstractGroundMotion):
    """(PGA m/s^2, PGV m/s) of each pulse of a batch, flat, from its closed
    forms on `_PULSE_POINTS` points from its start (or t = 0, where the
    analyses start, if it starts before) to its end."""
    shape = motion.batch_shape
    flat = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, shape).reshape(-1), motion
    )
    # From t = 0, where the analyses (and the other measures' samples) start:
    # a pulse may begin before it (t0 > -gamma / (2 f_p)).
    start = np.maximum(np.reshape(np.asarray(flat.start_time), -1), 0.0)
    stop = np.reshape(np.asarray(flat.end_time), -1)
    fraction = np.linspace(0.0, 1.0, _PULSE_POINTS)
    t = start[:, None] + (stop - start)[:, None] * fraction
    if isinstance(flat, MPPulse):
        # A pulse of many cycles (gamma up to 1e5) has fewer points a cycle
        # than its peaks need: its peaks lie within a cycle of its envelope's
        # peak t0 (or of where the pulse is cut at t = 0), read there as finely.
        period = 1.0 / np.reshape(np.asarray(flat.frequency), -1)
        centre = np.clip(np.reshape(np.asarray(flat.t0), -1), start, stop)
        low = np.maximum(centre - 2 * period, start)
        high = np.minimum(centre + 2 * period, stop)
        t = np.concatenate([t, low[:, None] + (high - low)[:, None] * fraction], 1)
    t = jnp.asarray(t)
    acc = jax.vmap(lambda m, t: m.acceleration(t))(flat, t)
    vel = jax.vmap(lambda m, t: m.velocity(t))(flat, t)
    return np.abs(np.asarray(acc)).max(axis=1), np.abs(np.asarray(vel)).max(axis=1)


def _integrals(rows, dt, length):
    """Of each row of samples, x_g'' linear between them: (v, d, arias, cav)
    at the samples, each the exact integral from t = 0 (v in m/s, d in m,
    the running integrals of x_g''^2 in m^2/s^3 and of |x_g''| in m/s),
    held after the row's last sample."""
    a0, a1 = rows[:, :-1], rows[:, 1:]
    h = dt[:, None]
    inside = np.arange(1, rows.shape[1]) < length[:, None]

    def running(increments):
        increments = np.where(inside, increments, 0.0)
        zero = np.zeros((rows.shape[0], 1))
        return np.concatenate([zero, np.cumsum(increments, axis=1)], axis=1)

    v = running(0.5 * h * (a0 + a1))
    # d_{k+1} = d_k + v_k h + h^2 (2 a_k + a_{k+1}) / 6
    d = running(v[:, :-1] * h + h * h * (2 * a0 + a1) / 6)
    square = running(h * (a0 * a0 + a0 * a1 + a1 * a1) / 3)
    # |x_g''| over an interval: a trapezoid, or two triangles where it crosses 0.
    total = np.abs(a0) + np.abs(a1)
    crossing = (a0 * a1 < 0) & (total > 0)
    absolute = np.where(
        crossing,
        h * (a0 * a0 + a1 * a1) / (2 * np.where(crossing, total, 1.0)),
        0.5 * h * total,
    )
    return v, d, square, running(absolute)


def _baseline_corrected(v, d, dt, length):
    """(v, d) less the velocity's least-squares fit c1 t + c2 t^2 over each
    row's samples (zero at t = 0, where the record starts from rest: a
    constant and a linear offset of x_g''), and its integral
    c1 t^2 / 2 + c2 t^3 / 3 from the displacement."""
    v, d = v.copy(), d.copy()
    for r, (h, n) in enumerate(zip(dt, length)):
        t = h * np.arange(n)
        basis = np.stack([t, t * t], axis=1)
        (c1, c2), *_ = np.linalg.lstsq(basis, v[r, :n], rcond=None)
        v[r, :n] -= c1 * t + c2 * t * t
        d[r, :n] -= c1 * t * t / 2 + c2 * t**3 / 3
        v[r, n:], d[r, n:] = v[r, n - 1], d[r, n - 1]
    return v, d


def _significant_duration(square, dt, low=0.05, high=0.95):
    """D5-95 (s) of each row from the running integral of x_g''^2 at the
    samples, the times of 5% and 95% of its total linear between samples;
    NaN for a record of zeros, which has none."""
    times = []
    for row, h in zip(square, dt):
        total = row[-1]
        if total <= 0:
            times.append(np.nan)
            continue
        t = h * np.arange(row.size)
        at = np.interp([low * total, high * total], row, t)
        times.append(at[1] - at[0])
    return np.array(times)


def intensity_measure(
    motion: AbstractGroundMotion,
    measure: str = "pga",
    *,
    slenderness=None,
    size=None,
    baseline: bool = False,
) -> np.ndarray:
    """An intensity measure of a ground motion, or of each motion of a batch.

    The measures are those of the horizontal motion (a vertical part is
    left out). A record's measures are exact for its samples, x_g'' linear
    between them,
    over its duration: velocity and displacement are its exact integrals
    from rest at t = 0, and their peaks are taken over the samples. With
    `baseline`, PGV and PGD (and "pgv_ratio") are those of the velocity less
    its least-squares fit c1 t + c2 t^2 over the record (a constant and a
    linear offset of the acceleration, which a raw record's drift shows as
    a velocity that does not return to zero) and of its integral; without
    (the default), of the record as it is, as PEER's processed records are
    meant to be read. A scaled record's measures are those of its
    unscaled samples, scaled. A closed-form pulse is sampled as in
    `response_spectrum` (its PGA and PGV from its closed forms on 20,001
    points).

    - "pga": max |x_g''| (m/s^2); "pgv": max |x_g'| (m/s); "pgd": max |x_g|
      (m).
    - "sa:T": the pseudo-spectral acceleration at period T s and 5% damping
      (m/s^2; `response_spectrum`), e.g. "sa:1.0".
    - "arias": pi / (2 g) times the integral of x_g''^2 (m/s); "cav": the
      integral of |x_g''| (m/s); "d5_95": the time from 5% to 95% of the
      Arias intensity (s; NaN for a record of zeros), each crossing
      interpolated linearly between the samples of the cumulative Arias
      intensity (within one sample interval of the exact crossing).
    - "tp": the pulse period T_p = 1 / f_p (s): a pulse's own, a record's
      from the Mavroeidis-Papageorgiou pulse fitted to its velocity
      (`fit_pulse`: seconds a record; a scale factor does not change it).
    - Of a block (give `slenderness` lambda and `size` r, m; tan alpha =
      1 / lambda, p = sqrt(3 g / (4 r))): "pga_ratio", PGA / (g tan alpha);
      "pgv_ratio", PGV p / (g tan alpha); "frequency_ratio", omega_p / p,
      omega_p the pulse's circular frequency (an `MPPulse` or `SinePulse`).

    Args:
        motion: a record, a suite, scaled or not, or a pulse (batched or not).
        measure: one of the names above; default "pga".
        slenderness: the block's lambda = h / b (> 0), for the block's
            measures.
        size: the block's half-diagonal r (m, > 0), for "pgv_ratio" and
            "frequency_ratio".
        baseline: remove the velocity's quadratic baseline first (records;
            "pgv", "pgd", "pgv_ratio"); default False.

    Returns:
        The measure of each motion of the batch, shape `motion.batch_shape`.

    Raises:
        ValueError: an unknown measure or a period outside [0.001, 100] s, a block's
            measure without the block, or "frequency_ratio" of a record.

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> t = np.arange(0.0, 10.0, 0.01)
        >>> rec = jr.Record(3.0 * np.sin(2 * np.pi * t), 0.01)
        >>> float(jr.intensity_measure(rec, "pga")), round(float(
        ...     jr.intensity_measure(rec, "arias")), 3)  # pi / (2 g) 4.5 9.99
        (3.0, 7.201)
        >>> round(float(jr.intensity_measure(rec, "pga_ratio", slenderness=4.0)), 3)
        1.223
    """
    name, period = parse_measure(measure)
    if isinstance(motion, WithVertical):  # the measures of its horizontal part
        motion = motion.horizontal
    _check_inputs(motion, name, measure, slenderness, size)
    flag("baseline", baseline)
    shape = tuple(motion.batch_shape)
    if name == "sa":
        spectrum = response_spectrum(motion, check_periods(period), SA_DAMPING)
        return spectrum.pseudo_acceleration[..., 0]
    if name == "frequency_ratio":
        omega = 2 * np.pi * np.asarray(motion.frequency)
        p = np.sqrt(3 * GRAVITY / (4 * np.asarray(size)))
        return np.broadcast_to(omega / p, shape).copy()
    if name == "tp":
        return _pulse_period(motion)
    if name in ("pga", "pgv", "pga_ratio", "pgv_ratio"):
        return _peak_measure(motion, name, slenderness, size, baseline)
    return _integral_measure(motion, name, baseline)


def _pulse_period(motion) -> np.ndarray:
    """T_p = 1 / f_p (s) of each motion: a pulse's, or of the pulse fitted to
    each record's velocity (once a row of unscaled samples)."""
    shape = tuple(motion.batch_shape)
    if not isinstance(motion, Record):
        if not isinstance(motion, (MPPulse, SinePulse)):
            raise ValueError(
                "measure 'tp' needs a pulse (MPPulse or SinePulse) or a record, "
                f"got {type(motion).__name__}"
            )
        return np.broadcast_to(1.0 / np.asarray(motion.frequency), shape).copy()
    from ._fit import fit_pulse

    samples = motion_samples(motion)
    periods = []
    for row, dt, n in zip(samples.rows, samples.dt, samples.length):
        fit = fit_pulse(Record(row[: int(n)], float(dt)))
        periods.append(1.0 / float(fit.pulse.frequency))
    return samples.of_member(np.array(periods))


def _check_inputs(motion, name, measure, slenderness, size) -> None:
    """`ValueError` unless `motion` is a ground motion with what the measure
    `name` needs (a block's measure: the block; a frequency: a pulse)."""
    if name in BLOCK_MEASURES:
        if slenderness is None or (name != "pga_ratio" and size is None):
            needs = "`slenderness`" + (" and `size`" if name != "pga_ratio" else "")
            raise ValueError(f"measure {measure!r} needs the block's {needs}")
        positive("slenderness", slenderness)
        if size is not None:
            positive("size", size)
    if name == "frequency_ratio" and not isinstance(motion, (MPPulse, SinePulse)):
        raise ValueError(
            "measure 'frequency_ratio' needs a pulse (MPPulse or SinePulse) with "
            f"a frequency, got {type(motion).__name__}"
        )
    if not isinstance(motion, AbstractGroundMotion):
        raise ValueError(
            f"`motion` must be a ground motion (a Record or a pulse), got "
            f"{type(motion).__name__}"
        )


def _peak_measure(motion, name, slenderness, size, baseline=False):
    """PGA, PGV, or the block's PGA / (g tan alpha) and PGV p / (g tan alpha)."""
    if isinstance(motion, Record):
        samples = motion_samples(motion)
        v, d, _, _ = _integrals(samples.rows, samples.dt, samples.length)
        if baseline:
            v, _ = _baseline_corrected(v, d, samples.dt, samples.length)
        pga = np.asarray(motion.peak_acceleration)  # (its padding left out)
        pgv = samples.per_member(np.abs(v).max(axis=1))
    else:
        shape = tuple(motion.batch_shape)
        pga, pgv = (np.reshape(x, shape) for x in _pulse_peaks(motion))
    if name == "pga":
        return pga
    if name == "pgv":
        return pgv
    tan_alpha = 1.0 / np.asarray(slenderness)
    if name == "pga_ratio":
        return pga / (GRAVITY * tan_alpha)
    p = np.sqrt(3 * GRAVITY / (4 * np.asarray(size)))
    return pgv * p / (GRAVITY * tan_alpha)


def _integral_measure(motion, name, baseline=False):
    """PGD, Arias intensity, CAV or D5-95, from the exact integrals of the
    motion's samples."""
    samples = motion_samples(motion)
    v, d, square, absolute = _integrals(samples.rows, samples.dt, samples.length)
    if baseline and isinstance(motion, Record):
        v, d = _baseline_corrected(v, d, samples.dt, samples.length)
    if name == "pgd":
        return samples.per_member(np.abs(d).max(axis=1))
    if name == "arias":
        arias = np.pi / (2 * GRAVITY) * square[:, -1]
        return samples.per_member(arias, power=2)
    if name == "cav":
        return samples.per_member(absolute[:, -1])
    return samples.of_member(_significant_duration(square, samples.dt))
