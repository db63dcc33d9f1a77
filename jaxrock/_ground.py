"""Ground motions: what every motion answers, and the closed-form pulses
(Mavroeidis-Papageorgiou, one-sine); records are `_record.py`."""

import abc
import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._misc import (
    AbstractChecked,
    Constraint,
    broadcast_batch_shape,
    describe_values,
    finite,
    greater_than_zero,
    parameter,
    real_number,
    scale_factors,
)
from ._trig import sincos


class AbstractGroundMotion(AbstractChecked):
    """A horizontal ground motion, read as its acceleration x_g''(t) (m/s^2).

    An analysis starts at t = 0 with the block and base at rest and reads the
    motion through `acceleration(t)` (m/s^2, t in s) and `end_time` (s), when
    the excitation ends; what the motion does before t = 0 is ignored, and the
    analyses run until the block's fate is decided, for at most 60 s after
    `end_time` (`simulate`'s `duration`). The motions are
    `MPPulse`, `SinePulse` and `Record`. Their parameters may carry batch axes
    (an ensemble of motions, for `behavior_map` and `fragility`).

    Examples:
        >>> import jaxrock as jr
        >>> motion = jr.SinePulse(amplitude=3.0, frequency=2.0)
        >>> isinstance(motion, jr.AbstractGroundMotion), float(motion.end_time)
        (True, 0.5)
    """

    @abc.abstractmethod
    def acceleration(self, t: Float[Array, ""]) -> Float[Array, ""]:
        """x_g''(t) in m/s^2."""

    @property
    @abc.abstractmethod
    def end_time(self) -> Float[Array, ""]:
        """When the excitation ends (s)."""

    @abc.abstractmethod
    def acceleration_bound(
        self, t0: Float[Array, ""], t1: Float[Array, ""]
    ) -> Float[Array, ""]:
        """A bound of |x_g''| over [t0, t1] (m/s^2; t1 >= t0), tight when the
        interval is short, inf when none is cheap (the rest rule reads it)."""

    def acceleration_lower_bound(self, t0, t1) -> Float[Array, ""]:
        """A lower bound of x_g'' itself over [t0, t1] (m/s^2): of a vertical
        motion, it bounds g_eff from below (the rest rule reads it). By
        default -`acceleration_bound`."""
        return -self.acceleration_bound(t0, t1)

    @property
    def start_time(self) -> Float[Array, ""]:
        """When the excitation starts (s)."""
        return jnp.zeros_like(self.end_time)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The shape of a batch of motions (their parameters broadcast)."""
        return broadcast_batch_shape(self)

    def names(self) -> tuple | None:
        """A name per motion of a batch (flat, C order); None if unnamed."""
        return None

    def unlabeled(self) -> "AbstractGroundMotion":
        """The motion without static labels (what compiled code takes)."""
        return self

    def scaled(self, factor) -> "AbstractGroundMotion":
        """The motion times `factor` (> 0; an array adds leading axes)."""
        raise NotImplementedError(f"{type(self).__name__} cannot be scaled")

    @property
    def max_step(self) -> Float[Array, ""] | None:
        """Largest integration step (s), so that no uplift hides inside a step."""
        return None

    @property
    def peak_acceleration_bound(self) -> Float[Array, "..."]:
        """A bound of |x_g''| over all times (m/s^2; inf when none is known):
        read of a vertical motion, whose peak bounds how far it lowers g."""
        return self.acceleration_bound(self.start_time, self.end_time)

    def with_vertical(self, vertical: "AbstractGroundMotion") -> "AbstractGroundMotion":
        """This horizontal motion with the ground's vertical acceleration
        `vertical` (any motion, positive upward, m/s^2): the block then feels
        g + a_v(t) instead of g (docs/model.md, "Vertical ground motion").

        Two closed forms stay closed forms; with a record on either side the
        result is a `Record` whose samples carry both, a closed form sampled
        at the record's `dt` (linear between samples, like the record).
        Records must share one `dt`; the shorter is padded with zeros.

        Examples:
            >>> import jaxrock as jr
            >>> pulse = jr.near_fault_pulse("San Fernando PCD/SN")
            >>> shaken = pulse.with_vertical(jr.SinePulse(3.0, 2.0))
            >>> float(shaken.end_time) == float(pulse.end_time)
            True
        """
        from ._vertical import with_vertical

        return with_vertical(self, vertical)


# Pieces of an interval over which a pulse bounds x_g'' (`AbstractPulse`):
# Taylor's bound from each piece's start is within C (w / n)^2 / 2 of the
# true range, C the curvature bound.
PULSE_BOUND_PIECES = 8


class AbstractPulse(AbstractGroundMotion):
    """A closed-form pulse: x_g'' smooth within [`start_time`, `end_time`]
    and zero outside, with bounds of its rate (`jerk_bound`) and curvature
    (`acceleration_curvature`), and a largest step (`max_step`).

    The bounds let a block at rest on a fixed base step to just before
    |x_g''| could reach its uplift level (`_signal.ClosedFormSignal`), and
    bound x_g'' over an interval for the rest rule (`acceleration_bound`).
    """

    @property
    @abc.abstractmethod
    def jerk_bound(self) -> Float[Array, "..."]:
        """A bound of |(x_g'')'| over the pulse (m/s^3)."""

    @property
    @abc.abstractmethod
    def acceleration_curvature(self) -> Float[Array, "..."]:
        """A bound of |(x_g'')''| over the pulse (m/s^4)."""

    def _range(self, t0, t1):
        """(lower, upper) bounds of x_g'' over [t0, t1] (m/s^2): over each of
        `PULSE_BOUND_PIECES` equal pieces, the tightest of three (`_piece`),
        and their extremes."""
        t0 = jnp.asarray(t0, dtype=float)
        w = (t1 - t0) / PULSE_BOUND_PIECES
        starts = t0 + w * jnp.arange(PULSE_BOUND_PIECES)
        lower, upper = jax.vmap(lambda s: self._piece(s, s + w))(starts)
        return jnp.min(lower, axis=0), jnp.max(upper, axis=0)

    def _piece(self, t0, t1):
        """(lower, upper) bounds of x_g'' over [t0, t1] (m/s^2), the tightest
        of three: the peak; a = x_g''(t0) -+ `jerk_bound` (t1 - t0); and,
        where x_g'' is smooth over the interval (no end of the pulse inside,
        where its rate jumps), Taylor's with the curvature C:
        a + min(0, a' w - C w^2 / 2) <= x_g'' <= a + max(0, a' w + C w^2 / 2),
        w = t1 - t0, a' = (x_g'')'(t0) (the bounds of a' s -+ C s^2 / 2 on
        [0, w] are at its ends). Zero on both sides outside the pulse."""
        a, rate = jax.jvp(self.acceleration, (t0,), (jnp.ones_like(t0),))
        w = t1 - t0
        jerk, peak = self.jerk_bound * w, self.peak_acceleration_bound
        bend = 0.5 * self.acceleration_curvature * w * w
        start, end = self.start_time, self.end_time
        outside = (t0 >= end) | (t1 <= start)
        smooth = outside | ((t0 >= start) & (t1 <= end))
        upper = jnp.minimum(a + jerk, peak)
        upper = jnp.where(
            smooth, jnp.minimum(upper, a + jnp.maximum(rate * w + bend, 0.0)), upper
        )
        lower = jnp.maximum(a - jerk, -peak)
        lower = jnp.where(
            smooth, jnp.maximum(lower, a + jnp.minimum(rate * w - bend, 0.0)), lower
        )
        return jnp.where(outside, 0.0, lower), jnp.where(outside, 0.0, upper)

    def acceleration_bound(self, t0, t1):
        lower, upper = self._range(t0, t1)
        return jnp.maximum(upper, -lower)

    def acceleration_lower_bound(self, t0, t1):
        return self._range(t0, t1)[0]

    @property
    @abc.abstractmethod
    def max_step(self) -> Float[Array, "..."]:
        """Largest step while the ground moves (s), so that no excursion of
        |x_g''| beyond a level hides inside a step."""


class MPPulse(AbstractPulse):
    """Mavroeidis & Papageorgiou (2003) near-fault velocity pulse.

    The ground velocity (m/s), for |t - t0| <= gamma / (2 f_p) and zero
    elsewhere (Eq. 3.1 of the paper):

        v(t) = A/2 [1 + cos(2 pi f_p (t - t0) / gamma)] cos(2 pi f_p (t - t0) + nu)

    and the ground acceleration x_g''(t) = v'(t) (m/s^2), continuous. The
    pulse lasts gamma / f_p (s), its envelope peaking at t0; the default t0
    starts it at t = 0. `near_fault_pulse` gives the pulses fitted to
    near-fault records.

    Args:
        amplitude: A, the velocity amplitude (m/s), finite.
        frequency: f_p, the prevailing frequency (Hz), > 0.
        gamma: the oscillatory character (-), > 1 and <= 1e5.
        phase: nu, the phase angle (degrees), within +-1e6.
        t0: the time of the envelope's peak (s), > -gamma / (2 f_p) (a pulse
            that ends after t = 0); default gamma / (2 f_p).

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> pulse = jr.MPPulse(amplitude=0.5, frequency=1.0, gamma=2.0, phase=0.0)
        >>> float(pulse.end_time), float(pulse.velocity(1.0))  # v(t0) = A
        (2.0, 0.5)
    """

    amplitude: Float[Array, "..."] = parameter("amplitude", "m/s")
    frequency: Float[Array, "..."] = parameter("frequency", "Hz")
    gamma: Float[Array, "..."] = parameter("gamma", "1")
    phase: Float[Array, "..."] = parameter("phase", "degree")
    t0: Float[Array, "..."] = parameter("t0", "s")

    def __init__(self, amplitude, frequency, gamma, phase, t0=None):
        self.amplitude = amplitude
        self.frequency = frequency
        self.gamma = gamma
        self.phase = phase
        if t0 is None:
            t0 = 0.5 * real_number("gamma", gamma) / real_number("frequency", frequency)
        self.t0 = t0

    def constraints(self):
        # `sincos` is exact for arguments below 8e5 rad; the pulse's stay below
        # pi gamma + |nu|, so both get a bound far above any physical pulse.
        return [
            finite("amplitude", self.amplitude),
            greater_than_zero("frequency", self.frequency),
            Constraint(
                "gamma", self.gamma, lambda v: (v > 1) & (v <= 1e5), "> 1 and <= 1e5"
            ),
            Constraint(
                "phase", self.phase, lambda v: abs(v) <= 1e6, "within +-1e6 degrees"
            ),
            # The pulse must end after t = 0, where the analysis starts.
            Constraint(
                "t0",
                self.t0,
                lambda v: v + self.half_duration > 0,
                "> -gamma / (2 f_p) (a pulse that ends after t = 0)",
            ),
        ]

    def describe(self):
        return (
            f"MP pulse (A = {describe_values(self.amplitude)} m/s, "
            f"f_p = {describe_values(self.frequency)} Hz, "
            f"gamma = {describe_values(self.gamma)}, "
            f"nu = {describe_values(self.phase)} deg)"
        )

    @property
    def start_time(self):
        return self.t0 - self.half_duration

    @property
    def half_duration(self):
        return 0.5 * self.gamma / self.frequency

    def acceleration(self, t):
        # tau is clipped to the pulse (zero outside), which keeps the arguments
        # of `sincos` small.
        tau = jnp.clip(t - self.t0, -self.half_duration, self.half_duration)
        w = 2.0 * jnp.pi * self.frequency
        sin_e, cos_e = sincos(w * tau / self.gamma)
        sin_p, cos_p = sincos(w * tau + jnp.deg2rad(self.phase))
        a = -(self.amplitude * jnp.pi * self.frequency / self.gamma) * (
            sin_e * cos_p + self.gamma * sin_p * (1.0 + cos_e)
        )
        return jnp.where(jnp.abs(t - self.t0) <= self.half_duration, a, 0.0)

    @property
    def peak_acceleration_bound(self):
        # |sin cos + gamma sin (1 + cos)| <= 1 + 2 gamma.
        return (
            jnp.abs(self.amplitude)
            * jnp.pi
            * self.frequency
            / self.gamma
            * (1.0 + 2.0 * self.gamma)
        )

    @property
    def jerk_bound(self):
        # The jerk is at most |A| pi f_p / gamma * 2 pi f_p (1/gamma + 2 + 2 gamma).
        w = 2.0 * jnp.pi * self.frequency
        jerk = jnp.abs(self.amplitude) * 0.5 * w * w / self.gamma
        return jerk * (1.0 / self.gamma + 2.0 + 2.0 * self.gamma)

    @property
    def acceleration_curvature(self):
        # |(x_g'')''| <= |A| pi f_p / gamma (2 pi f_p)^2
        #   (1/gamma^2 + 3/gamma + 3 + 2 gamma).
        w = 2.0 * jnp.pi * self.frequency
        g = self.gamma
        curvature = jnp.abs(self.amplitude) * 0.5 * w**3 / g
        return curvature * (1.0 / g**2 + 3.0 / g + 3.0 + 2.0 * g)

    def scaled(self, factor) -> "MPPulse":
        factor = scale_factors(factor)
        shape = factor.shape + self.batch_shape
        factor = factor.reshape(factor.shape + (1,) * len(self.batch_shape))
        return MPPulse(
            *(
                jnp.broadcast_to(x, shape)
                for x in (factor * self.amplitude, self.frequency, self.gamma)
            ),
            jnp.broadcast_to(self.phase, shape),
            jnp.broadcast_to(self.t0, shape),
        )

    def velocity(self, t):
        """Ground velocity v(t) (m/s)."""
        tau = t - self.t0
        w = 2.0 * jnp.pi * self.frequency
        v = (
            0.5
            * self.amplitude
            * (1.0 + jnp.cos(w * tau / self.gamma))
            * jnp.cos(w * tau + jnp.deg2rad(self.phase))
        )
        return jnp.where(jnp.abs(tau) <= self.half_duration, v, 0.0)

    @property
    def end_time(self):
        return self.t0 + self.half_duration

    @property
    def max_step(self):
        # x_g'' oscillates at f_p: 32 steps a cycle keep any excursion of |x_g''|
        # beyond a threshold that lies inside one step below 0.5% of its peak.
        return 1.0 / (32.0 * self.frequency)


class SinePulse(AbstractPulse):
    """One-sine acceleration pulse, x_g'' = a_p sin(2 pi f_p t) for 0 <= t <= 1 / f_p.

    The ground acceleration (m/s^2) is zero outside the pulse, which lasts
    1 / f_p (s); the ground velocity a_p / (2 pi f_p) [1 - cos(2 pi f_p t)]
    (m/s) returns to zero at its end. It is the pulse of the rocking
    literature's overturning spectra (Makris & Roussos 2000, type A), which
    `overturning_spectrum` sweeps.

    Args:
        amplitude: a_p, the peak acceleration (m/s^2), finite.
        frequency: f_p, the pulse's frequency (Hz), > 0.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> pulse = jr.SinePulse(amplitude=3.0, frequency=2.0)
        >>> float(pulse.end_time), float(pulse.acceleration(0.125))
        (0.5, 3.0)
    """

    amplitude: Float[Array, "..."] = parameter("amplitude", "m/s^2")
    frequency: Float[Array, "..."] = parameter("frequency", "Hz")

    def constraints(self):
        return [
            finite("amplitude", self.amplitude),
            greater_than_zero("frequency", self.frequency),
        ]

    def acceleration(self, t):
        a = self.amplitude * jnp.sin(2.0 * jnp.pi * self.frequency * t)
        return jnp.where((t >= 0) & (t <= self.end_time), a, 0.0)

    @property
    def peak_acceleration_bound(self):
        return jnp.abs(self.amplitude)

    @property
    def jerk_bound(self):
        return jnp.abs(self.amplitude) * 2.0 * jnp.pi * self.frequency

    @property
    def acceleration_curvature(self):
        return jnp.abs(self.amplitude) * (2.0 * jnp.pi * self.frequency) ** 2

    def scaled(self, factor) -> "SinePulse":
        factor = scale_factors(factor)
        shape = factor.shape + self.batch_shape
        factor = factor.reshape(factor.shape + (1,) * len(self.batch_shape))
        return SinePulse(
            jnp.broadcast_to(factor * self.amplitude, shape),
            jnp.broadcast_to(self.frequency, shape),
        )

    def velocity(self, t):
        """Ground velocity (m/s); it keeps its final value after the pulse."""
        w = 2.0 * jnp.pi * self.frequency
        tc = jnp.clip(t, 0.0, self.end_time)
        return self.amplitude / w * (1.0 - jnp.cos(w * tc))

    @property
    def end_time(self):
        return 1.0 / self.frequency

    @property
    def max_step(self):
        return 1.0 / (32.0 * self.frequency)


# Table 3.1 of the paper (Mavroeidis & Papageorgiou 2003 fits):
# name -> (A in cm/s, gamma, nu in degrees, f_p in Hz)
_TABLE_3_1 = {
    "Parkfield C02/SN": (60.0, 1.700, 100.0, 0.500),
    "San Fernando PCD/SN": (115.0, 1.600, 180.0, 0.680),
    "Bucharest BRI/SN": (62.0, 2.400, 200.0, 0.470),
    "Tabas TAB/SP": (104.0, 2.200, 180.0, 0.190),
    "Imperial Valley E04/SN": (71.0, 1.900, 305.0, 0.225),
    "Imperial Valley E05/SN": (84.0, 1.900, 300.0, 0.255),
    "Imperial Valley E06/SN": (96.0, 2.100, 265.0, 0.260),
    "Imperial Valley E07/SN": (79.0, 2.100, 25.0, 0.275),
    "Imperial Valley EMO/SN": (78.0, 2.300, 0.0, 0.340),
    "Northridge JFA/SN": (87.0, 2.300, 100.0, 0.330),
    "Northridge RRS/SN": (142.0, 1.700, 20.0, 0.800),
    "Northridge SCG/SN": (93.0, 2.500, 0.0, 0.340),
    "Northridge SCH/SN": (80.0, 2.300, 0.0, 0.330),
    "Northridge NWS/SN": (94.0, 1.700, 200.0, 0.370),
    "Aigion AEG/Lon": (44.5, 1.450, 75.0, 1.400),
    "Aigion AEG/Tran": (61.0, 1.200, 205.0, 1.480),
    "Izmit ARC/SN": (41.0, 1.380, 225.0, 0.140),
    "Izmit SKR/SP": (67.0, 1.023, 5.0, 0.105),
    "Izmit GBZ/SN": (34.5, 2.200, 220.0, 0.210),
    "Izmit GBZ/SP": (28.0, 1.800, 85.0, 0.165),
}

NEAR_FAULT_PULSES: tuple[str, ...] = tuple(_TABLE_3_1)


def near_fault_pulse(name: str, scale: float = 1.0) -> MPPulse:
    """The Mavroeidis & Papageorgiou pulse fitted to a near-fault record.

    The 20 fits of Table 3.1 of the paper, by record name: A (m/s), f_p (Hz),
    gamma and nu (degrees) of an `MPPulse` that starts at t = 0.
    `NEAR_FAULT_PULSES` lists the names.

    Args:
        name: the record, e.g. "Northridge JFA/SN" (event, station and
            component).
        scale: the factor (-) on the amplitude A, one real number, finite
            and > 0; default 1.

    Returns:
        The `MPPulse`.

    Raises:
        ValueError: an unknown `name` (the message lists the known ones), or
            a `scale` that is not one real number, finite and > 0 (a string,
            a boolean, None or an array is refused, not converted), or one
            that makes the amplitude overflow.

    Examples:
        >>> import jaxrock as jr
        >>> jr.near_fault_pulse("Northridge JFA/SN").describe()
        'MP pulse (A = 0.87 m/s, f_p = 0.33 Hz, gamma = 2.3, nu = 100 deg)'
        >>> float(jr.near_fault_pulse("Northridge JFA/SN", scale=2.0).amplitude)
        1.74
    """
    if name not in _TABLE_3_1:
        raise ValueError(
            f"unknown pulse {name!r}; choose one of: {', '.join(NEAR_FAULT_PULSES)}"
        )
    scale = scale_factors(scale, "scale")
    if scale.ndim:
        raise ValueError(f"`scale` must be one number, got shape {scale.shape}")
    scale = float(scale)
    amplitude_cm, gamma, phase, frequency = _TABLE_3_1[name]
    amplitude = scale * amplitude_cm / 100.0
    if not math.isfinite(amplitude):
        raise ValueError(
            f"`scale` times the pulse's amplitude ({amplitude_cm / 100.0:g} m/s) "
            f"must be finite, got scale = {scale:g}"
        )
    return MPPulse(amplitude, frequency, gamma, phase)
