"""Elastic design spectra from their code parameters: ASCE 7-22 (Sec. 11.4.6)
and Eurocode 8 (EN 1998-1, Sec. 3.2.2.2, types 1 and 2)."""

import numpy as np

from ._misc import grid_axis, positive

# EN 1998-1 Tables 3.2 (type 1) and 3.3 (type 2): S, T_B, T_C, T_D (s) by
# ground type.
_EUROCODE8 = {
    1: {
        "A": (1.0, 0.15, 0.4, 2.0),
        "B": (1.2, 0.15, 0.5, 2.0),
        "C": (1.15, 0.20, 0.6, 2.0),
        "D": (1.35, 0.20, 0.8, 2.0),
        "E": (1.4, 0.15, 0.5, 2.0),
    },
    2: {
        "A": (1.0, 0.05, 0.25, 1.2),
        "B": (1.35, 0.05, 0.25, 1.2),
        "C": (1.5, 0.10, 0.25, 1.2),
        "D": (1.8, 0.10, 0.30, 1.2),
        "E": (1.6, 0.05, 0.25, 1.2),
    },
}


def _check_periods(periods) -> np.ndarray:
    """`periods` as a 1-D float array of finite values > 0 (`ValueError`):
    the closed forms hold at any period."""
    periods = grid_axis("periods", periods)
    positive("periods", periods)
    return periods


def _number(name: str, value, low=0.0) -> float:
    """`value` as a float, finite and > `low` (`ValueError` naming `name`)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = float("nan")
    if not (np.isfinite(x) and x > low):
        raise ValueError(f"`{name}` must be one finite number > {low:g}, got {value!r}")
    return x


def _key_in(key, table) -> bool:
    """Whether `key` is a key of `table` (False for an unhashable one, such
    as a list)."""
    try:
        return key in table
    except TypeError:
        return False


def asce7_spectrum(periods, sds: float, sd1: float, tl: float) -> np.ndarray:
    """The ASCE 7-22 design response spectrum (Sec. 11.4.6), Sa in g.

    With T_0 = 0.2 S_D1 / S_DS and T_S = S_D1 / S_DS:

        Sa = S_DS (0.4 + 0.6 T / T_0)   T < T_0
        Sa = S_DS                       T_0 <= T <= T_S
        Sa = S_D1 / T                   T_S < T <= T_L
        Sa = S_D1 T_L / T^2             T > T_L

    Args:
        periods: the periods T (s), finite and > 0; a number or a 1-D array.
        sds: S_DS, the design spectral acceleration at short periods (g).
        sd1: S_D1, the design spectral acceleration at 1 s (g).
        tl: T_L, the long-period transition period (s).

    Returns:
        Sa (g) at each period, a 1-D array (times 9.81 for m/s^2).

    Raises:
        ValueError: periods not finite and > 0, or a parameter that is not
            one finite number > 0 (T_L must exceed T_S = S_D1 / S_DS).

    Examples:
        >>> import jaxrock as jr
        >>> jr.asce7_spectrum([0.0001, 0.2, 1.0, 2.0, 16.0], sds=1.0, sd1=0.6, tl=8.0)
        array([0.4005 , 1.     , 0.6    , 0.3    , 0.01875])
    """
    periods = _check_periods(periods)
    sds, sd1, tl = _number("sds", sds), _number("sd1", sd1), _number("tl", tl)
    t0, ts = 0.2 * sd1 / sds, sd1 / sds
    if tl <= ts:
        raise ValueError(f"`tl` must exceed T_S = sd1 / sds = {ts:g} s, got {tl:g}")
    t = periods
    return np.select(
        [t < t0, t <= ts, t <= tl],
        [sds * (0.4 + 0.6 * t / t0), np.full_like(t, sds), sd1 / t],
        sd1 * tl / t**2,
    )


def eurocode8_spectrum(
    periods,
    ag: float,
    ground_type: str = "B",
    spectrum_type: int = 1,
    damping: float = 0.05,
) -> np.ndarray:
    """The Eurocode 8 horizontal elastic response spectrum (EN 1998-1,
    Sec. 3.2.2.2), Se in the units of `ag`.

    With S, T_B, T_C and T_D of the ground type (Table 3.2 for type 1,
    Table 3.3 for type 2) and eta = sqrt(10 / (5 + 100 zeta)) >= 0.55:

        Se = ag S (1 + T / T_B (2.5 eta - 1))   0 <= T <= T_B
        Se = 2.5 ag S eta                       T_B <= T <= T_C
        Se = 2.5 ag S eta T_C / T               T_C <= T <= T_D
        Se = 2.5 ag S eta T_C T_D / T^2         T_D <= T

    Args:
        periods: the periods T (s), finite and > 0; a number or a 1-D array.
        ag: the design ground acceleration on type A ground (a_g = gamma_I
            a_gR), e.g. in m/s^2 or g.
        ground_type: "A" to "E".
        spectrum_type: 1 (surface-wave magnitude above 5.5) or 2.
        damping: the viscous damping ratio zeta, > 0 and < 1; default 0.05
            (eta = 1).

    Returns:
        Se at each period, in the units of `ag`, a 1-D array.

    Raises:
        ValueError: periods not finite and > 0, `ag` not one finite number
            > 0, an unknown `ground_type` or `spectrum_type`, or a damping
            outside (0, 1).

    Examples:
        >>> import jaxrock as jr
        >>> jr.eurocode8_spectrum([0.1, 0.3, 1.0, 4.0], ag=2.0, ground_type="C")
        array([4.025  , 5.75   , 3.45   , 0.43125])
    """
    periods = _check_periods(periods)
    ag = _number("ag", ag)
    if isinstance(spectrum_type, bool) or not _key_in(spectrum_type, _EUROCODE8):
        raise ValueError(f"`spectrum_type` must be 1 or 2, got {spectrum_type!r}")
    if not _key_in(ground_type, _EUROCODE8[spectrum_type]):
        raise ValueError(
            f"`ground_type` must be one of A, B, C, D, E, got {ground_type!r}"
        )
    damping = _number("damping", damping)
    if damping >= 1:
        raise ValueError(f"`damping` must be > 0 and < 1, got {damping!r}")
    s, tb, tc, td = _EUROCODE8[spectrum_type][ground_type]
    eta = max(np.sqrt(10.0 / (5.0 + 100.0 * damping)), 0.55)
    plateau = 2.5 * ag * s * eta
    t = periods
    return np.select(
        [t <= tb, t <= tc, t <= td],
        [
            ag * s * (1 + t / tb * (2.5 * eta - 1)),
            np.full_like(t, plateau),
            plateau * tc / t,
        ],
        plateau * tc * td / t**2,
    )
