"""Scale factors of records: to a peak ground acceleration or velocity, to a
spectral acceleration at one period, or to a target spectrum over a period
range (`Record.scaled_to`, `Record.scaled_to_spectrum`)."""

import numpy as np

from ._response_spectrum import (
    PERIOD_RANGE,
    check_periods,
    period_in_range,
    response_spectrum,
)


def factor_to(record, *, pga=None, pgv=None, sa=None) -> np.ndarray:
    """The factor per record of `record` that scales it to one target (see
    `Record.scaled_to`)."""
    given = [k for k, v in (("pga", pga), ("pgv", pgv), ("sa", sa)) if v is not None]
    if len(given) != 1:
        raise ValueError(
            "give exactly one of `pga` (m/s^2), `pgv` (m/s) and "
            "`sa` = (period in s, Sa in m/s^2)"
        )
    name = given[0]
    if name == "sa":
        if not (isinstance(sa, (tuple, list)) and len(sa) == 2):
            raise ValueError(f"`sa` must be (period in s, Sa in m/s^2), got {sa!r}")
        period = np.asarray(sa[0], dtype=float)
        if period.ndim or not period_in_range(period):
            low, high = PERIOD_RANGE
            raise ValueError(
                f"`sa`'s period must be one number in [{low}, {high}] (s), "
                f"got {sa[0]!r}"
            )
        target = sa[1]
    else:
        target = pga if name == "pga" else pgv
    target = np.asarray(target, dtype=float)
    if not np.all(np.isfinite(target) & (target > 0)):
        raise ValueError(f"`{name}` must be finite and > 0, got {target.tolist()}")
    shape = np.shape(record.pga)
    if target.shape not in ((), shape):
        raise ValueError(
            f"`{name}` must be one number or one per record, of shape {shape}, "
            f"got shape {target.shape}"
        )
    if name == "sa":
        now = response_spectrum(record, float(period)).pseudo_acceleration[..., 0]
    else:
        now = record.pga if name == "pga" else record.pgv
    if np.any(now <= 0):
        raise ValueError(f"a record with zero {name.upper()} cannot be scaled")
    return np.broadcast_to(target / now, now.shape)


def factor_to_spectrum(record, periods, target, damping, each) -> np.ndarray:
    """The factor per record (or one for the suite) that fits `record`'s log
    spectrum to `target`'s over `periods` (see `Record.scaled_to_spectrum`)."""
    periods = check_periods(periods)
    target = np.asarray(target, dtype=float)
    if target.shape != periods.shape or not np.all(np.isfinite(target) & (target > 0)):
        raise ValueError(
            f"`target` must hold one Sa (m/s^2), finite and > 0, per period "
            f"({periods.size}), got shape {target.shape}"
        )
    sa = np.asarray(response_spectrum(record, periods, damping).pseudo_acceleration)
    if np.any(sa <= 0):
        raise ValueError("a record with zero Sa in `periods` cannot be scaled")
    if each:
        factor = np.exp(np.mean(np.log(target / sa), axis=-1))
    else:
        mean = sa.reshape(-1, periods.size).mean(axis=0)
        one = np.exp(np.mean(np.log(target / mean)))
        factor = np.full(sa.shape[:-1], one)
    return factor
