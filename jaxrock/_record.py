"""Recorded accelerograms: one record, or a suite of records of different
lengths and time steps, with their labels."""

import dataclasses
from collections.abc import Sequence
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._ground import AbstractGroundMotion
from ._misc import (
    GRAVITY,
    Constraint,
    computed_once,
    describe_values,
    greater_than_zero,
    in_range,
    parameter,
    range_maxima,
    real_number,
    scale_factors,
)
from ._translation import TranslationTables

# The allowed sample interval `dt` (s); strong-motion records are sampled
# every 1e-4 to 0.05 s. Below: events are located to 1e-12 s + 1e-14 t
# (`_events.py`), and a record whose samples come closer than that (at dt =
# 1e-300 s the whole record is) is lost in the tolerance: an uplift and a
# rotation of exactly 0, reported as a success. 1e-6 s keeps a sample
# interval 1e6 tolerances long at t = 0, and 1e4 at t = 1e4 s. Above: a
# sample every second describes nothing faster than 0.5 Hz, and the bound
# keeps the end time, (n - 1) dt, finite (at dt = 1e308 it is inf).
DT_MIN, DT_MAX = 1e-6, 1.0


def _labels(value, n):
    """A label per record of a suite: `value` repeated, or a sequence of n."""
    if isinstance(value, (tuple, list)):
        if len(value) != n:
            raise ValueError(f"expected {n} labels, got {len(value)}")
        return tuple(value)
    return (value,) * n


class Record(AbstractGroundMotion):
    """A recorded accelerogram: `acceleration` (m/s^2) sampled every `dt` (s),
    from 1e-6 to 1 s.

    Sample k is at t = k dt; x_g'' is linear between samples and zero after
    the last one. A suite (`Record.stack`) holds several records along leading
    axes, each with its own `dt` and number of samples (`length`); the rest of
    its row is padding that no result depends on. A scaled record or suite
    (`scaled`, `scaled_to`) keeps the unscaled samples and a factor per
    record: the samples of a suite at many intensities are stored once, and
    `samples` multiplies them out. `factor` (keyword) builds one: a factor
    per record of the batch (> 0), whose shape is the batch's and ends with
    the leading axes of `acceleration`; `dt` and `length` then have the
    batch's shape.

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
    # max |x_g''| of `unscaled` over sample ranges [k, k + 2^l) (`with_peaks`),
    # or None.
    peaks: Float[Array, "*records levels n"] | None
    # A linear isolator's response in translation to the unscaled records
    # (`with_translation`), or None.
    translation: TranslationTables | None
    # Inside a map under a suite: the suite's record this one reads (`row`),
    # else None.
    index: Int[Array, ""] | None
    shared_by_cells: ClassVar[bool] = True
    name: str | tuple | None = eqx.field(static=True)
    azimuth: float | tuple | None = eqx.field(static=True)
    rsn: int | tuple | None = eqx.field(static=True)

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
    ):
        self.unscaled = acceleration
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
        self.peaks = None
        self.translation = None
        self.index = None

    def __check_init__(self):
        shape = np.shape(self.unscaled)
        if len(shape) < 1 or shape[-1] < 2:
            raise ValueError(
                "`acceleration` must hold at least 2 samples (along its last axis), "
                f"got shape {shape}"
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

    def constraints(self):
        n = self.sample_count
        out = [
            Constraint(
                "acceleration",
                self.unscaled,
                lambda v: v == v,
                "finite (no NaN or inf)",
            ),
            in_range("dt", self.dt, DT_MIN, DT_MAX, "s"),
            Constraint(
                "length", self.length, lambda v: (v >= 2) & (v <= n), f">= 2 and <= {n}"
            ),
        ]
        if self.factor is not None:
            out.append(greater_than_zero("factor", self.factor))
        return out

    @property
    def samples(self) -> Float[Array, "*batch n"]:
        """x_g'' at the samples (m/s^2), with `batch_shape` leading axes."""
        if self.factor is None:
            return self.unscaled
        return self.factor[..., None] * self.unscaled

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
        rows = [np.pad(np.asarray(r.samples), (0, n - r.sample_count)) for r in records]
        return cls(
            np.stack(rows),
            np.stack([np.asarray(r.dt) for r in records]),
            length=np.array([int(r.length) for r in records]),
            name=tuple(r.name for r in records),
            azimuth=tuple(r.azimuth for r in records),
            rsn=tuple(r.rsn for r in records),
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
        given = [
            k for k, v in (("pga", pga), ("pgv", pgv), ("sa", sa)) if v is not None
        ]
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
            if period.ndim or not (np.isfinite(period) and period > 0):
                raise ValueError(
                    "`sa`'s period must be one number, finite and > 0 (s), got "
                    f"{sa[0]!r}"
                )
            target = sa[1]
        else:
            target = pga if name == "pga" else pgv
        target = np.asarray(target, dtype=float)
        if not np.all(np.isfinite(target) & (target > 0)):
            raise ValueError(f"`{name}` must be finite and > 0, got {target.tolist()}")
        if name == "sa":
            from ._response_spectrum import response_spectrum

            now = response_spectrum(self, float(period)).pseudo_acceleration[..., 0]
        else:
            now = self.pga if name == "pga" else self.pgv
        if np.any(now <= 0):
            raise ValueError(f"a record with zero {name.upper()} cannot be scaled")
        factor = np.broadcast_to(target / now, now.shape)
        return self._rebuilt(jnp.asarray(factor), **self.labels())

    def scaled_to_spectrum(
        self, periods, target, *, damping: float = 0.05, each: bool = True
    ) -> "Record":
        """The record or suite scaled to a target spectrum over a period range.

        `periods` (s, finite and > 0) sample the range, `target` gives the
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
        from ._response_spectrum import check_periods, response_spectrum

        periods = check_periods(periods)
        target = np.asarray(target, dtype=float)
        if target.shape != periods.shape or not np.all(
            np.isfinite(target) & (target > 0)
        ):
            raise ValueError(
                f"`target` must hold one Sa (m/s^2), finite and > 0, per period "
                f"({periods.size}), got shape {target.shape}"
            )
        sa = np.asarray(response_spectrum(self, periods, damping).pseudo_acceleration)
        if np.any(sa <= 0):
            raise ValueError("a record with zero Sa in `periods` cannot be scaled")
        if each:
            factor = np.exp(np.mean(np.log(target / sa), axis=-1))
        else:
            mean = sa.reshape(-1, periods.size).mean(axis=0)
            one = np.exp(np.mean(np.log(target / mean)))
            factor = np.full(sa.shape[:-1], one)
        return self._rebuilt(jnp.asarray(factor), **self.labels())

    def labels(self, flat: bool = False) -> dict:
        """name, azimuth and rsn; with `flat`, as tuples over the records."""
        out = dict(name=self.name, azimuth=self.azimuth, rsn=self.rsn)
        if flat and not self.batch_shape:
            out = {k: (v,) for k, v in out.items()}
        return out

    def select(self, index) -> "Record":
        """Records by position in the suite (its motion axes flattened, C
        order): an int gives one record, an array of ints a suite."""
        n = self.sample_count
        rows = self.unscaled.reshape(-1, n)
        samples = rows[jnp.asarray(index) % rows.shape[0]]
        if self.factor is not None:
            samples = jnp.reshape(self.factor, -1)[index][..., None] * samples
        dt = jnp.reshape(self.dt, -1)[index]
        length = jnp.reshape(self.length, -1)[index]
        try:
            chosen = np.asarray(index)
        except jax.errors.TracerArrayConversionError:  # inside compiled code
            chosen = None
        picked = {}
        for key, values in self.labels(flat=True).items():
            if chosen is None:
                picked[key] = None
            elif chosen.ndim == 0:
                picked[key] = values[int(chosen)]
            else:
                picked[key] = tuple(values[int(j)] for j in chosen.reshape(-1))
        return Record(samples, dt, length=length, **picked)

    def names(self) -> tuple | None:
        names = self.labels(flat=True)["name"]
        return None if all(n is None for n in names) else names

    def unlabeled(self) -> "Record":
        """The record without labels: what compiled code takes (labels are
        static, so two labels would compile twice)."""
        out = Record(self.unscaled, self.dt, length=self.length, factor=self.factor)
        return eqx.tree_at(
            lambda r: (r.peaks, r.translation, r.index),
            out,
            (self.peaks, self.translation, self.index),
            is_leaf=lambda x: x is None,
        )

    def row(self, index) -> "Record":
        """Record `index` of the suite (its motion axes flattened, C order),
        as a view that reads the suite's arrays in place: what the lanes of a
        map under a suite take (`index` batched, the suite not), so that the
        samples are never copied per lane. Only the engines' methods
        (`acceleration`, `end_time`, `acceleration_bound`, `next_kink`) read
        a view."""

        def flat(x, tail=0):  # the batch's axes as one
            return None if x is None else x.reshape((-1,) + x.shape[x.ndim - tail :])

        translation = self.translation
        if translation is not None:
            translation = TranslationTables(
                flat(translation.states, 2),
                flat(translation.displacement_max, 1),
                flat(translation.acceleration_peaks, 2),
                flat(translation.displacement_peaks, 2),
                translation.scaled,
            )
        return eqx.tree_at(
            lambda r: (
                r.unscaled,
                r.dt,
                r.length,
                r.factor,
                r.peaks,
                r.translation,
                r.index,
            ),
            self.unlabeled(),
            (
                flat(self.unscaled, 1),
                flat(self.dt),
                flat(self.length),
                flat(self.factor),
                flat(self.peaks, 2),
                translation,
                jnp.asarray(index),
            ),
            is_leaf=lambda x: x is None,
        )

    def row_axes(self) -> "Record":
        """The `jax.vmap` in_axes of views from `row` with a lane axis: the
        index batched (0), the suite's arrays not (None)."""
        axes = jax.tree_util.tree_map(lambda _: None, self.row(0))
        return eqx.tree_at(lambda r: r.index, axes, 0, is_leaf=lambda x: x is None)

    def _read(self, array, *at):
        """array[at] of `unscaled`, `peaks` or a table of `translation` of this
        record: of the suite's
        record `index` for a view (the factors' axes lead the batch)."""
        if self.index is None:
            return array[at]
        row = self.index if self.factor is None else self.index % len(self.unscaled)
        return array[(row,) + at]

    def _of_batch(self, array):
        """This record's element of `dt`, `length` or `factor`."""
        return array if self.index is None else array[self.index]

    @property
    def _dt(self):
        return self._of_batch(self.dt)

    @property
    def _length(self):
        return self._of_batch(self.length)

    def _sample(self, k):
        """x_g'' at the samples k (m/s^2)."""
        a = self._read(self.unscaled, k)
        if self.factor is None:
            return a
        # Rounded as the product multiplied out (`samples`) would be: no
        # rewrite of XLA's, f a1 - f a0 -> f (a1 - a0), reaches across.
        return computed_once(self._of_batch(self.factor) * a)

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
        return (
            f"record ({label}{int(self.length)} samples, "
            f"dt = {describe_values(self.dt)} s)"
        )

    def acceleration(self, t):
        dt, length = self._dt, self._length
        x = t / dt
        k = jnp.clip(jnp.floor(x), 0, length - 2).astype(int)
        frac = x - k
        a0, a1 = self._sample(k), self._sample(k + 1)
        value = a0 + (a1 - a0) * frac
        return jnp.where((t >= 0) & (t <= (length - 1) * dt), value, 0.0)

    @property
    def end_time(self):
        return (self._length - 1) * self._dt

    def step_accelerations(self, times):
        """x_g'' at a step's times from two samples, not two at each time: a
        step of the flat loop ends at the next sample (`next_kink`), so x_g''
        is one line over it, that of the sample interval where it starts
        (the same arithmetic as `acceleration`). A longer step (a block at
        rest on a fixed base skipping to just before its next uplift, whose
        vector field reads no x_g'') reads its end exactly, and its inner
        times on that line. (The line is written out here and in
        `acceleration`: one helper for both compiled to a slower loop; the
        docs' performance page, "Choices in the code".)"""
        dt, length = self._dt, self._length
        index, kink = self._next_sample(times[0])
        k = jnp.clip(index - 1.0, 0, length - 2).astype(int)
        a0, a1 = computed_once((self._sample(k), self._sample(k + 1)))
        end = (length - 1) * dt

        def line(t):
            value = a0 + (a1 - a0) * (t / dt - k)
            return jnp.where((t >= 0) & (t <= end), value, 0.0)

        t1 = times[-1]
        last = jnp.where(t1 > kink, self.acceleration(t1), line(t1))
        return [line(t) for t in times[:-1]] + [last]

    def acceleration_bound(self, t0, t1):
        """max |x_g''| over [t0, t1]: x_g'' is linear between samples, so the
        largest of |x_g''(t0)|, |x_g''(t1)| and the samples between, read from
        at most `_BOUND_SAMPLES` samples after t0 (inf for a longer interval)."""
        n = self.sample_count
        dt = self._dt
        width = min(_BOUND_SAMPLES, n)
        first = jnp.floor(t0 / dt) + 1.0  # the first sample after t0
        start = jnp.clip(first, 0, n - width).astype(int)
        index = start + jnp.arange(width)
        near = self._sample(index)
        inside = (index >= first) & (index * dt < t1) & (index < self._length)
        ends = jnp.maximum(
            jnp.abs(self.acceleration(t0)), jnp.abs(self.acceleration(t1))
        )
        bound = jnp.maximum(ends, jnp.max(jnp.where(inside, jnp.abs(near), 0.0)))
        covered = (t1 < (start + width) * dt) | (t0 > self.end_time)
        return jnp.where(covered, bound, jnp.inf)

    def with_peaks(self) -> "Record":
        """The record with its table of peaks (`peaks`): max |x_g''| over every
        range of 2^l samples, l = 0, 1, ..., L - 1 (2^(L-1) >= n), so that
        `next_kink` finds the first sample above a level in L reads. Of a
        suite, one table a record, unless the tables would exceed
        `_PEAKS_BYTES` (a suite's resting blocks then step through its
        samples). Of a scaled record, the table of its unscaled samples.
        Traceable."""
        level = jnp.abs(self.unscaled)
        n = level.shape[-1]
        if level.size * _levels(n) * level.dtype.itemsize > _PEAKS_BYTES:
            return self
        return eqx.tree_at(
            lambda r: r.peaks, self, range_maxima(level), is_leaf=lambda x: x is None
        )

    def with_translation(self, base) -> "Record":
        """The record with `translation`: the tables of `base`'s response in
        translation (`_translation.py`; a `LinearIsolator`, one for every
        lane), None for other bases or where the tables would exceed
        `_PEAKS_BYTES`. Traceable.

        The tables are those of `samples` (the factors multiplied out: a
        scaled record's map equals, to the bit, that of its samples
        multiplied out), unless a suite holds several factors per record (at
        many intensities): then they are those of `unscaled`, one a record,
        read times each factor (the same response, linear in the factor, to
        the last bits).
        """
        n = self.sample_count
        per_factor = self.factor is not None and (
            self.batch_shape != np.shape(self.unscaled)[:-1]
        )
        # (Multiplied out as `samples` would be: no rewrite of XLA's reaches
        # across the product.)
        samples = self.unscaled if per_factor else computed_once(self.samples)
        if samples.size * (2 * _levels(n) + 3) * 8 > _PEAKS_BYTES:
            return self
        tables = base.translation_tables(samples, self.dt, self.length)
        if tables is not None:
            tables = dataclasses.replace(tables, scaled=not per_factor)
        return eqx.tree_at(
            lambda r: r.translation, self, tables, is_leaf=lambda x: x is None
        )

    def translation_tables(self):
        return self.translation

    def _next_sample(self, t):
        """The index of the first sample after t (a float) and its time (the
        same floats as dt * k)."""
        dt = self._dt
        k = jnp.floor(t / dt)
        times = [dt * (k + i) for i in (0.0, 1.0, 2.0)]
        index = jnp.where(times[0] > t, k, jnp.where(times[1] > t, k + 1.0, k + 2.0))
        kink = jnp.where(
            times[0] > t, times[0], jnp.where(times[1] > t, times[1], times[2])
        )
        return index, kink

    def quiet_end(self, t, level):
        """The first sample after t whose |x_g''| reaches `level` (its index,
        the record's length if none), from the table of peaks (NaN without
        one)."""
        if self.peaks is None:
            return jnp.full_like(t, jnp.nan)
        scale = 1.0 if self.factor is None else self._of_batch(self.factor)

        def peak(width_log, k):  # max |f x| = f max |x| (f > 0), exactly
            return scale * self._read(self.peaks, width_log, k)

        index, _ = self._next_sample(t)
        first = _first_at_least(peak, self.sample_count, index.astype(int), level)
        return first.astype(index.dtype)

    def sample_at(self, t):
        """(k, exact): the index of the sample nearest t, and whether t is its
        time (the floats of dt * k, as `next_kink` gives them) within the
        record."""
        dt = self._dt
        k = jnp.round(t / dt)
        return k, (dt * k == t) & (k <= self._length - 1)

    def sample_time(self, k):
        """The time of sample k (int): the floats of `next_kink`."""
        return self._dt * k

    def _scale(self):
        """The factor of this record's `translation` tables."""
        if self.factor is None or self.translation.scaled:
            return 1.0
        return self._of_batch(self.factor)

    def translation_state(self, k):
        """The base state (u, u') of `translation` at sample k (int)."""
        return self._scale() * self._read(self.translation.states, k)

    def translation_displacement_max(self, k):
        """max |u| of `translation` over [0, t_k] (m; k an int)."""
        return self._scale() * self._read(self.translation.displacement_max, k)

    def translation_first(self, k, acceleration, displacement):
        """The first sample interval from k (int) on over which a bound of
        `translation`'s |A| may reach `acceleration` (m/s^2) or of its |u|
        `displacement` (m); the record's last sample if none."""
        scale, n = self._scale(), self.sample_count
        tables = self.translation

        def first(table, level):
            def peak(width_log, i):
                return scale * self._read(table, width_log, i)

            return _first_at_least(peak, n, k, level)

        return jnp.minimum(
            first(tables.acceleration_peaks, acceleration),
            first(tables.displacement_peaks, displacement),
        )

    def step_end(self, t0, dt, kink):
        """Of a step of at most dt from t0 to the next sample `kink`: t0 + dt
        if the sample is n > 8 steps of dt away, else t0 + (kink - t0) / n,
        the first of n equal steps to it, and the sample itself for n = 1.

        Steps of dt and a short remainder would leave the step-size
        controller a step much shorter than it proposed, from which it grows
        the next one again: equal steps take fewer steps and err less (the
        docs' performance page, "Choices in the code")."""
        n = jnp.ceil((kink - t0) / dt)
        equal = jnp.where(n <= 1, kink, t0 + (kink - t0) / n)
        return jnp.where(n <= _EQUAL_STEPS, equal, t0 + dt)

    def quiet_holds(self, t, quiet_end):
        """`quiet_end` holds until t reaches that sample."""
        index, _ = self._next_sample(t)
        return quiet_end >= index

    def next_kink(self, t, quiet_below=None, quiet_end=None):
        """The first sample time after t (the same floats as dt * k), found
        from t alone: the cost of a step does not grow with the record.

        With `quiet_below` (m/s^2) and the table of `with_peaks`: the sample
        time before the first sample whose |x_g''| reaches `quiet_below`
        (`quiet_end`; linear between samples, |x_g''| stays below it until
        then), if that is later: a block at rest on a fixed base then skips
        to just before its next uplift in one step.
        """
        index, kink = self._next_sample(t)
        if quiet_below is not None and self.peaks is not None:
            if quiet_end is None:
                first = self.quiet_end(t, quiet_below)
            else:  # where it holds (a level of 0, a rocking lane: never)
                known = (quiet_below > 0) & (quiet_end >= index)
                first = jnp.where(known, quiet_end, index)
            later = jnp.minimum(first - 1, self._length - 1).astype(index.dtype)
            kink = jnp.where(later > index, self._dt * later, kink)
            index = jnp.maximum(index, later)
        return jnp.where(index <= self._length - 1, kink, jnp.inf)

    # -- intensity measures -----------------------------------------------------

    @property
    def peak_acceleration(self):
        return jnp.max(jnp.abs(self.samples), axis=-1)

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


# Samples `Record.acceleration_bound` reads at most.
_BOUND_SAMPLES = 16
# The largest table of peaks `Record.with_peaks` builds (bytes): 28 records of
# 18,000 samples take 62 MB.
_PEAKS_BYTES = 2**28


def _levels(n: int) -> int:
    """L, the levels of the table of peaks of n samples: 2^(L-1) >= n."""
    return max(1, (n - 1).bit_length() + 1)


def _first_at_least(peak, n, start, level):
    """The first sample index k >= start with |x_g''| >= level (n if none),
    by binary lifting on the table of peaks (`peak(l, k)`: the max over
    [k, k + 2^l) of a record of n samples)."""
    k = start
    for width_log in reversed(range(_levels(n))):
        width = 1 << width_log
        below = peak(width_log, jnp.clip(k, 0, n - 1)) < level
        k = jnp.where(below & (k < n), k + width, k)
    return jnp.minimum(k, n)


# A step within this many proposed steps of the next sample is one of equal
# steps to it (`Record.step_end`).
_EQUAL_STEPS = 8
