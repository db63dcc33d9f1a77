"""Floor motions: the absolute acceleration at a floor of a linear building
under a ground motion, exact at a record's samples."""

import jax
import jax.numpy as jnp
import numpy as np

from ._ground import AbstractGroundMotion
from ._misc import check
from ._record import Record
from ._response_spectrum import (
    check_periods,
    motion_samples,
    oscillator_coefficients,
)
from ._vertical import WithVertical

# After the ground stops, a floor keeps vibrating: the floor motion runs this
# many of the building's longest periods past the motion's end.
_TAIL_PERIODS = 10


@jax.jit
def _modal_states(starts, rows, coefficients):
    """(u, u') of each mode at every sample of each row (R, n), from rest:
    the exact recurrence of `oscillator_coefficients` (8, R, M) over x_g''
    linear between samples, from `starts` (x_g'' just after each sample) to
    `rows` (at the next). Returns two arrays (R, n, M)."""
    a11, a12, a21, a22, b0u, b1u, b0v, b1v = coefficients
    zero = jnp.zeros(a11.shape)

    def step(carry, x):
        u, v = carry
        a0, a1 = x[0][:, None], x[1][:, None]
        u, v = (
            a11 * u + a12 * v + b0u * a0 + b1u * a1,
            a21 * u + a22 * v + b0v * a0 + b1v * a1,
        )
        return (u, v), (u, v)

    _, (u, v) = jax.lax.scan(step, (zero, zero), (starts[:, :-1].T, rows[:, 1:].T))
    u = jnp.concatenate([zero[None], u]).transpose(1, 0, 2)
    v = jnp.concatenate([zero[None], v]).transpose(1, 0, 2)
    return u, v


def _per_mode(name: str, value, modes: int) -> np.ndarray:
    """One value per mode: a number for every mode, or a 1-D array of
    `modes` values."""
    x = np.asarray(value, dtype=float)
    if x.ndim > 1 or (x.ndim == 1 and x.size != modes):
        raise ValueError(
            f"`{name}` must be one number or one per mode ({modes}), got shape "
            f"{x.shape}"
        )
    return np.broadcast_to(x, (modes,))


def _floor_rows(samples, length, periods, damping, participation, ends: bool):
    """a_f at every sample of each row of `samples`, run to `length` samples
    (zero past it): the modes carried from rest, the rows of one dt in one
    compiled call. With `ends` (a record), x_g'' steps to zero just after a
    row's last sample, as a `Record` is zero after it."""
    n = int(np.max(length))
    rows = np.zeros((samples.rows.shape[0], n))
    width = min(n, samples.rows.shape[1])
    rows[:, :width] = samples.rows[:, :width]
    # Past its `length` a row is padding, which no result depends on: zero.
    rows[np.arange(n) >= samples.length[:, None]] = 0.0
    starts = rows.copy()
    if ends:
        starts[np.arange(rows.shape[0]), samples.length - 1] = 0.0
    floor = np.empty_like(rows)
    omega = 2.0 * np.pi / periods
    for dt in np.unique(samples.dt):
        mine = samples.dt == dt
        coefficients = np.concatenate(  # (8, modes)
            [
                oscillator_coefficients(periods[m : m + 1], damping[m], dt)
                for m in range(periods.size)
            ],
            axis=-1,
        )
        coefficients = np.repeat(coefficients[:, None, :], int(np.sum(mine)), axis=1)
        states = _modal_states(
            jnp.asarray(starts[mine]), jnp.asarray(rows[mine]), coefficients
        )
        u, v = map(np.asarray, states)
        ground = rows[mine][:, :, None]
        relative = -ground - 2.0 * damping * omega * v - omega**2 * u
        floor[mine] = rows[mine] + np.sum(participation * relative, axis=-1)
    return np.where(np.arange(n) < length[:, None], floor, 0.0)


def floor_motion(
    motion: AbstractGroundMotion, periods, damping=0.05, participation=1.0
) -> Record:
    """The absolute acceleration at a floor of a linear building.

    The building is given by its modes at the floor: periods T_n (s),
    damping ratios zeta_n and participations P_n = Gamma_n phi_n(floor)
    (the modal participation factor times the mode's value at the floor; a
    one-mode building, P = 1, is a single oscillator). Each mode's relative
    displacement u_n obeys u_n'' + 2 zeta_n omega_n u_n' + omega_n^2 u_n =
    -x_g'', and the floor's absolute acceleration is

        a_f = x_g'' + sum_n P_n u_n'',  u_n'' = -x_g'' - 2 zeta_n omega_n u_n'
              - omega_n^2 u_n.

    For a record, x_g'' is linear between its samples (and zero just after
    the last, as a `Record` is) and each mode is carried exactly from sample
    to sample (as `response_spectrum`), so a_f is exact at the samples; the
    floor motion is the `Record` of those samples
    (linear between them), running `10 max(T_n)` s past the ground motion's
    end, where the floor still vibrates. A closed-form pulse is sampled as
    `response_spectrum` samples it. A suite gives a suite, a scaled record a
    record with the same factors (a_f is linear in x_g''). Floor response
    spectra are `response_spectrum(floor_motion(...), ...)`.

    Args:
        motion: a `Record`, a suite, a scaled record, or a pulse.
        periods: T_n (s), in [0.001, 100] s: a number (one mode) or one per mode.
        damping: zeta_n, >= 0 and < 1: a number for every mode or one per mode;
            default 0.05.
        participation: P_n (-), finite: a number for every mode or one per
            mode; default 1.

    Returns:
        The floor's absolute acceleration as a `Record` (m/s^2, the motion's
        sample interval), named after the motion.

    Raises:
        ValueError: a parameter outside its range or of the wrong shape (the
            message names it), a motion that is not a ground motion, or one
            with a vertical part.

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> t = np.arange(0.0, 10.0, 0.01)
        >>> rec = jr.Record(np.sin(2 * np.pi * t), 0.01, name="sine")
        >>> floor = jr.floor_motion(rec, periods=1.0, damping=0.05)
        >>> floor.name, round(float(floor.end_time), 2)
        ('sine, floor (T = 1 s)', 19.99)
        >>> round(float(floor.pga / rec.pga), 1)  # at resonance: about 1 / (2 zeta)
        9.6
    """
    if (
        isinstance(motion, WithVertical)
        or getattr(motion, "vertical", None) is not None
    ):
        raise ValueError(
            "`motion` has a vertical part, which floor_motion does not filter "
            "(the building's modes are horizontal): pass its horizontal motion, "
            "and give the floor motion a vertical part with `with_vertical`"
        )
    periods = check_periods(periods)
    modes = periods.size
    damping = _per_mode("damping", damping, modes)
    check("damping", damping, lambda d: (d >= 0) & (d < 1), ">= 0 and < 1")
    participation = _per_mode("participation", participation, modes)
    check("participation", participation, np.isfinite, "finite")
    tail = _TAIL_PERIODS * float(np.max(periods))
    samples = motion_samples(motion, tail=tail)  # (a pulse's: with the tail)
    record = isinstance(motion, Record)
    # A record's rows run on past its end, where the ground is still.
    extra = np.round(tail / samples.dt).astype(int)
    length = samples.length + (extra if record else 0)
    floor = _floor_rows(samples, length, periods, damping, participation, record)
    n = floor.shape[-1]
    modes_label = ", ".join(f"{t:g}" for t in periods)
    if not record:  # a pulse, or a batch of pulses: one row a member
        batch = samples.batch_shape
        shape = batch + (n,)
        dt = samples.dt.reshape(batch) if batch else float(samples.dt[0])
        size = length.reshape(batch) if batch else int(length[0])
        return Record(floor.reshape(shape), dt, length=size)
    labels = motion.labels(flat=True)
    labels["name"] = tuple(
        None if x is None else f"{x}, floor (T = {modes_label} s)"
        for x in labels["name"]
    )
    if not motion.batch_shape:
        labels = {k: v[0] for k, v in labels.items()}
    unscaled = floor.reshape(np.shape(motion.unscaled)[:-1] + (n,))
    dt = np.asarray(motion.dt)
    return Record(
        unscaled,
        dt,
        length=np.asarray(motion.length) + np.round(tail / dt).astype(int),
        factor=motion.factor,
        **labels,
    )
