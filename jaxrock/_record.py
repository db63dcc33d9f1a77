"""Recorded accelerograms: one record, or a suite of records of different
lengths and time steps, with their labels."""

import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._ground import AbstractGroundMotion
from ._misc import (
    GRAVITY,
    Constraint,
    describe_values,
    in_range,
    parameter,
    real_number,
    scale_factors,
)

# The allowed sample interval `dt` (s); strong-motion records are sampled
# every 1e-4 to 0.05 s. Below: events are located to 1e-12 s + 1e-14 t
# (`_events.py`), and a record whose samples come closer than that (at dt =
# 1e-300 s the whole record is) is lost in the tolerance: an uplift and a
# rotation of exactly 0, reported as a success. 1e-6 s keeps a sample
# interval 1e6 tolerances long at t = 0, and 1e4 at t = 1e4 s. Above: a
# sample every second describes nothing faster than 0.5 Hz, and the bound
# keeps the end time, (n - 1) dt, finite (at dt = 1e308 it is inf).
DT_MIN, DT_MAX = 1e-6, 1.0
# The largest |x_g''| of a record's samples (m/s^2, 10,000 g), and the largest
# scale factor: far beyond any ground motion, far below where the squares of
# its Arias intensity overflow.
MAX_ACCELERATION, MAX_FACTOR = 1e5, 1e6


def _labels(value, n):
    """A label per record of a suite: `value` repeated, or a sequence of n."""
    if isinstance(value, (tuple, list)):
        if len(value) != n:
            raise ValueError(f"expected {n} labels, got {len(value)}")
        return tuple(value)
    return (value,) * n


# The names PEER gives a vertical component at the end of a record's name.
VERTICAL_COMPONENTS = {"UP", "DWN", "DOWN", "V", "VER", "VERT"}


def component(record: "Record") -> str:
    """The component at the end of a record's name (its header's second
    line: event, date, station, component), in capitals ("" if none)."""
    return str(record.name or "").rsplit(",", 1)[-1].strip().upper()


def is_vertical(record: "Record") -> bool:
    """Whether a record's name ends with a vertical component: its last
    comma-separated part is one of UP, DWN, DOWN, V, VER or VERT (any case),
    as the second header line of a PEER NGA file names it.

    Raises:
        ValueError: `record` is not a `Record` (a closed-form motion, such as
            `MPPulse`, has no name to tell its component by), or is a suite
            (ask of each record, `record.select(i)`).

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> down = jr.Record(np.zeros(3), 0.01, name="Pacoima Dam, DWN")
        >>> east = jr.Record(np.zeros(3), 0.01, name="Pacoima Dam, 254")
        >>> jr.records.is_vertical(down), jr.records.is_vertical(east)
        (True, False)
    """
    if not isinstance(record, Record):
        raise ValueError(
            "`record` must be a Record, whose name gives its component, got "
            f"{type(record).__name__}"
        )
    if isinstance(record.name, tuple):
        raise ValueError(
            f"`record` must be one record, not a suite of {len(record.name)}: "
            "ask of each record (`record.select(i)`)"
        )
    return component(record) in VERTICAL_COMPONENTS


class Record(AbstractGroundMotion):
    """A recorded accelerogram: `acceleration` (m/s^2, each sample within
    +-1e5) sampled every `dt` (s), from 1e-6 to 1 s.

    Sample k is at t = k dt; x_g'' is linear between samples and zero after
    the last one. A suite (`Record.stack`) holds several records along leading
    axes, each with its own `dt` and number of samples (`length`); the rest of
    its row is padding that no result depends on. A scaled record or suite
    (`scaled`, `scaled_to`) keeps the unscaled samples and a factor per
    record: the samples of a suite at many intensities are stored once, and
    `samples` multiplies them out. `factor` (keyword) builds one: a factor
    per record of the batch (> 0 and <= 1e6), whose shape is the batch's and
    ends with the leading axes of `acceleration`; `dt` and `length` then have
    the batch's shape.

    `vertical` (keyword, m/s^2, positive upward) holds the ground's vertical
    acceleration at the same samples (`with_vertical` pairs two records, or
    a record and a closed form); scaled with the record, it lowers or raises
    the gravity the block feels (docs/model.md, "Vertical ground motion").

    Labels for titles and tables, static (they never enter a computation):
    `name` (event, station and component; "" is none), `azimuth` (the component's
    direction, degrees clockwise from north; None if unknown) and `rsn` (the
    PEER record sequence number; None if unknown). Of a suite, tuples.

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> t = np.arange(0.0, 10.0, 0.01)
        >>> rec = jr.Record(3.0 * np.sin(2 * np.pi * t), 0.01, name="sine")
        >>> rec.end_time, rec.scaled(2.0).peak_acceleration
        (Array(9.99, dtype=float64), Array(6., dtype=float64))
    """

    # x_g'' at the samples before `factor` (m/s^2): a record per leading index,
    # the last axes of the batch (`batch_shape` adds the factors' axes).
    unscaled: Float[Array, "*records n"] = parameter("acceleration", "m/s^2")
    dt: Float[Array, "*batch"] = parameter("dt", "s")
    length: Int[Array, "*batch"]
    # The scale factor of each record of the batch (> 0), or None: 1.
    factor: Float[Array, "*batch"] | None
    name: str | tuple | None = eqx.field(static=True)
    azimuth: float | tuple | None = eqx.field(static=True)
    rsn: int | tuple | None = eqx.field(static=True)
    # The vertical acceleration at the samples before `factor` (m/s^2, upward),
    # of the shape of `unscaled`; None: none.
    vertical: Float[Array, "*records n"] | None = eqx.field(
        converter=lambda x: None if x is None else real_number("vertical", x)
    )

    def __init__(
        self,
        acceleration,
        dt,
        *,
        length=None,
        name=None,
        azimuth=None,
        rsn=None,
        factor=None,
        vertical=None,
    ):
        self.unscaled = acceleration
        self.vertical = vertical
        self.dt = dt
        self.factor = None if factor is None else real_number("factor", factor)
        n = np.shape(self.unscaled)[-1] if np.ndim(self.unscaled) else 0
        length = n if length is None else length
        self.length = jnp.broadcast_to(
            jnp.asarray(length, dtype=int), jnp.shape(self.dt)
        )
        if self.batch_shape:  # a suite: one label per record
            count = int(np.prod(self.batch_shape))
            name, azimuth, rsn = (_labels(v, count) for v in (name, azimuth, rsn))
            name = tuple(None if n == "" else n for n in name)
        elif name == "":
            name = None
        self.name, self.azimuth, self.rsn = name, azimuth, rsn

    def __check_init__(self):
        shape = np.shape(self.unscaled)
        if len(shape) < 1 or shape[-1] < 2:
            raise ValueError(
                "`acceleration` must hold at least 2 samples (along its last axis), "
                f"got shape {shape}"
            )
        if self.vertical is not None and np.shape(self.vertical) != shape:
            raise ValueError(
                f"`vertical` must have the shape of `acceleration`, {shape}, got "
                f"{np.shape(self.vertical)}"
            )
        records = shape[:-1]
        if self.batch_shape[len(self.batch_shape) - len(records) :] != records:
            raise ValueError(
                f"`factor` must have a shape that ends with {records} (a factor "
                f"per record), got {self.batch_shape}"
            )
        if np.shape(self.dt) != self.batch_shape:
            raise ValueError(
                f"`dt` must have shape {self.batch_shape} (one per record), got "
                f"{np.shape(self.dt)}"
            )
        azimuths = self.azimuth if isinstance(self.azimuth, tuple) else [self.azimuth]
        for azimuth in azimuths:
            if azimuth is not None and not np.isfinite(real_number("azimuth", azimuth)):
                raise ValueError(f"`azimuth` must be finite (degrees), got {azimuth}")

    def constraints(self):
        n = self.sample_count
        out = [
            Constraint(
                "acceleration",
                self.unscaled,
                lambda v: abs(v) <= MAX_ACCELERATION,
                f"finite and within +-{MAX_ACCELERATION:g} m/s^2",
            ),
            in_range("dt", self.dt, DT_MIN, DT_MAX, "s"),
            Constraint(
                "length", self.length, lambda v: (v >= 2) & (v <= n), f">= 2 and <= {n}"
            ),
        ]
        if self.factor is not None:
            out.append(
                Constraint(
                    "factor",
                    self.factor,
                    lambda v: (v > 0) & (v <= MAX_FACTOR),
                    f"finite, > 0 and <= {MAX_FACTOR:g}",
                )
            )
        if self.vertical is not None:
            out.append(
                Constraint(
                    "vertical",
                    self.vertical,
                    lambda v: abs(v) <= MAX_ACCELERATION,
                    f"finite and within +-{MAX_ACCELERATION:g} m/s^2",
                )
            )
        return out

    @property
    def samples(self) -> Float[Array, "*batch n"]:
        """x_g'' at the samples (m/s^2), with `batch_shape` leading axes."""
        if self.factor is None:
            return self.unscaled
        return self.factor[..., None] * self.unscaled

    @property
    def vertical_samples(self) -> Float[Array, "*batch n"] | None:
        """The vertical acceleration at the samples (m/s^2, upward), with
        `batch_shape` leading axes; None without one."""
        if self.vertical is None or self.factor is None:
            return self.vertical
        return self.factor[..., None] * self.vertical

    def _rebuilt(self, factor=None, **labels) -> "Record":
        """The record with `labels`, times `factor` if given (an array whose
        shape ends with the batch shape: leading axes are new), its samples
        not multiplied out."""
        shape = np.broadcast_shapes(np.shape(factor), self.batch_shape)
        total = self.factor
        if factor is not None:
            total = factor if total is None else factor * total
            total = jnp.broadcast_to(total, shape)
        return Record(
            self.unscaled,
            jnp.broadcast_to(self.dt, shape),
            length=jnp.broadcast_to(self.length, shape),
            factor=total,
            vertical=self.vertical,
            **labels,
        )

    # -- building ---------------------------------------------------------------

    @classmethod
    def stack(cls, records: Sequence["Record"]) -> "Record":
        """A suite: the records along a leading motion axis, each keeping its own
        samples, `dt`, end time and labels (shorter ones padded with zeros).

        `behavior_map` under a suite has shape (n_records, n_slenderness,
        n_size), and each cell equals the same cell under its record alone.
        """
        records = list(records)
        if not records or not all(isinstance(r, Record) for r in records):
            raise ValueError("`records` must be a non-empty list of Record")
        if any(r.batch_shape != () for r in records):
            raise ValueError("`records` must be single records, not suites")
        n = max(r.sample_count for r in records)

        def rows(samples):
            return np.stack(
                [np.pad(np.asarray(s), (0, n - np.size(s))) for s in samples]
            )

        vertical = None
        if any(r.vertical is not None for r in records):  # zero where none
            vertical = rows(
                r.samples * 0.0 if r.vertical is None else r.vertical_samples
                for r in records
            )
        return cls(
            rows(r.samples for r in records),
            np.stack([np.asarray(r.dt) for r in records]),
            length=np.array([int(r.length) for r in records]),
            name=tuple(r.name for r in records),
            azimuth=tuple(r.azimuth for r in records),
            rsn=tuple(r.rsn for r in records),
            vertical=vertical,
        )

    def scaled(self, factor) -> "Record":
        """The record times `factor` (> 0). An array of factors adds leading
        axes: one record at many intensities (a suite: every record at every
        factor, the factors' axes first). The samples are not copied per
        factor (see `samples`)."""
        factor = scale_factors(factor)
        batch = self.batch_shape
        labels = self.labels()
        if factor.ndim:
            labels = {
                k: v * int(factor.size) for k, v in self.labels(flat=True).items()
            }
        factor = factor.reshape(factor.shape + (1,) * len(batch))
        return self._rebuilt(factor, **labels)

    def scaled_to(self, *, pga=None, pgv=None, sa=None) -> "Record":
        """The record scaled to a peak ground acceleration `pga` (m/s^2), a
        peak ground velocity `pgv` (m/s), or a spectral acceleration
        `sa = (period, value)`: Sa(period s) at 5% damping = value (m/s^2,
        `response_spectrum`). Exactly one of the three; a target is a scalar
        or one per record of a suite.

        Examples:
            >>> import numpy as np, jaxrock as jr
            >>> t = np.arange(0.0, 10.0, 0.01)
            >>> rec = jr.Record(np.sin(2 * np.pi * t), 0.01)
            >>> scaled = rec.scaled_to(sa=(1.0, 4.9))
            >>> round(float(jr.intensity_measure(scaled, "sa:1.0")), 12)
            4.9
        """
        from ._scaling import factor_to

        factor = factor_to(self, pga=pga, pgv=pgv, sa=sa)
        return self._rebuilt(jnp.asarray(factor), **self.labels())

    def scaled_to_spectrum(
        self, periods, target, *, damping: float = 0.05, each: bool = True
    ) -> "Record":
        """The record or suite scaled to a target spectrum over a period range.

        `periods` (s, in [0.001, 100]) sample the range, `target` gives the
        target's pseudo-spectral acceleration there (m/s^2, > 0; e.g.
        `9.81 * jr.asce7_spectrum(periods, ...)`), `damping` the spectra's.
        With `each` (the default) every record gets the factor that fits its
        log spectrum to the target's in least squares,
        ln f_i = mean_k ln(target_k / Sa_i(T_k)); without, the suite gets one
        factor, the least-squares fit of the log of its mean spectrum,
        ln f = mean_k ln(target_k / mean_i Sa_i(T_k)) (the suite's mean is
        what ASCE 7-22 Sec. 16.2.3 compares with the target). A record whose
        Sa is 0 at a period of the range is refused.

        Examples:
            >>> import numpy as np, jaxrock as jr
            >>> t = np.arange(0.0, 20.0, 0.01)
            >>> rec = jr.Record(np.sin(2 * np.pi * t) * np.exp(-0.2 * t), 0.01)
            >>> periods = np.linspace(0.5, 2.0, 16)
            >>> target = 3.0 * jr.response_spectrum(rec, periods).pseudo_acceleration
            >>> round(float(rec.scaled_to_spectrum(periods, target).factor), 12)
            3.0
        """
        from ._scaling import factor_to_spectrum

        factor = factor_to_spectrum(self, periods, target, damping, each)
        return self._rebuilt(jnp.asarray(factor), **self.labels())

    def labels(self, flat: bool = False) -> dict:
        """name, azimuth and rsn; with `flat`, as tuples over the records."""
        out = dict(name=self.name, azimuth=self.azimuth, rsn=self.rsn)
        if flat and not self.batch_shape:
            out = {k: (v,) for k, v in out.items()}
        return out

    def select(self, index) -> "Record":
        """Records by position in the suite (its motion axes flattened, C
        order): an int gives one record, an array of ints a suite.

        Raises:
            ValueError: a concrete `index` that is not an integer (or an array
                of integers) in [-count, count), count being the number of
                records (the message names the range).
        """
        try:
            chosen = np.asarray(index)
        except jax.errors.TracerArrayConversionError:  # inside compiled code
            chosen = None
        count = math.prod(self.batch_shape)
        if chosen is not None and (
            chosen.dtype.kind not in "iu"
            or ((chosen < -count) | (chosen >= count)).any()
        ):
            what = "an integer" if chosen.ndim == 0 else "integers"
            raise ValueError(
                f"`index` must be {what} in [{-count}, {count}), got {index!r}"
            )
        n = self.sample_count

        def pick(unscaled):
            if unscaled is None:
                return None
            rows = unscaled.reshape(-1, n)
            samples = rows[jnp.asarray(index) % rows.shape[0]]
            if self.factor is not None:
                samples = jnp.reshape(self.factor, -1)[index][..., None] * samples
            return samples

        samples, vertical = pick(self.unscaled), pick(self.vertical)
        dt = jnp.reshape(self.dt, -1)[index]
        length = jnp.reshape(self.length, -1)[index]
        picked = {}
        for key, values in self.labels(flat=True).items():
            if chosen is None:
                picked[key] = None
            elif chosen.ndim == 0:
                picked[key] = values[int(chosen)]
            else:
                picked[key] = tuple(values[int(j)] for j in chosen.reshape(-1))
        return Record(samples, dt, length=length, vertical=vertical, **picked)

    def names(self) -> tuple | None:
        names = self.labels(flat=True)["name"]
        return None if all(n is None for n in names) else names

    def unlabeled(self) -> "Record":
        """The record without labels: what compiled code takes (labels are
        static, so two labels would compile twice)."""
        return Record(
            self.unscaled,
            self.dt,
            length=self.length,
            factor=self.factor,
            vertical=self.vertical,
        )

    # -- what the engines read ----------------------------------------------------

    @property
    def batch_shape(self) -> tuple[int, ...]:
        if self.factor is not None:
            return tuple(np.shape(self.factor))
        return tuple(np.shape(self.unscaled)[:-1])

    @property
    def sample_count(self) -> int:
        return int(np.shape(self.unscaled)[-1])

    def describe(self):
        if self.batch_shape:
            count = int(np.prod(self.batch_shape))
            return f"suite of {count} records (dt = {describe_values(self.dt)} s)"
        label = f"{self.name}, " if self.name else ""
        vertical = "" if self.vertical is None else ", with its vertical"
        return (
            f"record ({label}{int(self.length)} samples, "
            f"dt = {describe_values(self.dt)} s{vertical})"
        )

    def acceleration(self, t):
        """x_g''(t) (m/s^2), linear between the samples, 0 outside the record."""
        from ._signal import RecordSignal

        return RecordSignal(self).acceleration(t)

    @property
    def end_time(self):
        return (self.length - 1) * self.dt

    def acceleration_bound(self, t0, t1):
        from ._signal import RecordSignal

        return RecordSignal(self).acceleration_bound(t0, t1)

    # -- intensity measures -----------------------------------------------------

    @property
    def peak_acceleration(self):
        # Over each record's own `length` samples: the rest is padding.
        inside = jnp.arange(self.sample_count) < self.length[..., None]
        return jnp.max(jnp.where(inside, jnp.abs(self.samples), 0.0), axis=-1)

    @property
    def pga(self) -> np.ndarray:
        """Peak ground acceleration (m/s^2), one per record."""
        return np.asarray(self.peak_acceleration)

    @property
    def pgv(self) -> np.ndarray:
        """Peak ground velocity (m/s), one per record: the trapezoidal integral
        of the samples (no baseline correction)."""
        a = np.asarray(self.samples)
        dt = np.asarray(self.dt)[..., None]
        inside = np.arange(1, a.shape[-1]) < np.asarray(self.length)[..., None]
        dv = np.where(inside, 0.5 * (a[..., 1:] + a[..., :-1]) * dt, 0.0)
        return np.max(np.abs(np.cumsum(dv, axis=-1)), axis=-1, initial=0.0)

    @property
    def pga_in_g(self) -> np.ndarray:
        return self.pga / GRAVITY
