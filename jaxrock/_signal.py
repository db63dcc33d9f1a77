"""Signals: a ground motion as the engines read it inside compiled code.

A user's motion (`MPPulse`, `SinePulse`, `Record`) is a value: its parameters
and what every motion answers (x_g''(t), the end of the excitation, a bound of
|x_g''| over an interval). The engines read more: where a step must end (a
record's samples, the kinks of x_g''), where a block at rest on a fixed base
could next uplift (so that a step may skip to there), x_g'' at a step's stage
times in one evaluation. A signal answers these, with the tables they read
(a record's peaks, a linear isolator's translation), built once before the
loop by `_scene.prepare`:

- `ClosedFormSignal` wraps a closed-form motion; under an `AbstractPulse`
  (its curvature bounded) a block at rest on a fixed base steps to just
  before |x_g''| could reach its uplift level;
- `RecordSignal` reads a record's samples in place (a suite's row: `row`),
  its steps ending at the samples, and skips samples with its table of
  peaks and its translation tables.
"""

import abc
import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ._ground import AbstractGroundMotion, AbstractPulse
from ._misc import GRAVITY, computed_once, range_maxima
from ._record import Record
from ._translation import TranslationTables
from ._vertical import WithVertical


class AbstractAcceleration(eqx.Module):
    """What the vector field and the event conditions read of the ground:
    x_g''(t) and the gravity the block feels (m/s^2)."""

    @abc.abstractmethod
    def acceleration(self, t: Float[Array, ""]) -> Float[Array, ""]:
        """x_g''(t) (m/s^2)."""

    def gravity(self, t: Float[Array, ""]):
        """g_eff(t) = g + a_v(t) (m/s^2), a_v the ground's vertical
        acceleration (upward). Without a vertical motion, g itself as the
        Python float `GRAVITY`: the arithmetic of such a scene is the same
        as if g were written in."""
        del t
        return GRAVITY


class StillGround(AbstractAcceleration):
    """No horizontal ground motion: what the root find of a map's rocking
    lanes on a fixed base reads of the ground (only their uplift conditions,
    in translation, read it); g_eff that of `vertical` (the lanes' signal
    under vertical ground motion, whose free flight the root find locates),
    else g."""

    vertical: AbstractAcceleration | None = None

    def acceleration(self, t):
        return jnp.zeros_like(t)

    def gravity(self, t):
        if self.vertical is None:
            return GRAVITY
        return self.vertical.gravity(t)


class AbstractSignal(AbstractAcceleration):
    """A ground motion as the engines read it (module docstring).

    `limits_steps(resting)`, static: whether `next_kink` ends steps (a
    record's at every sample; a pulse's only for a block at rest on a fixed
    base, `resting`); without, a step ends where the controller puts it.
    """

    @property
    @abc.abstractmethod
    def end_time(self) -> Float[Array, ""]:
        """When the excitation ends (s)."""

    @property
    @abc.abstractmethod
    def max_step(self) -> Float[Array, ""] | None:
        """Largest step while the ground moves (s); None: no limit."""

    @property
    def step_bound(self) -> Float[Array, ""]:
        """A bound of every step while the ground moves (s; inf: none), for
        the conditions that must see what a step may hide (`condition_base`):
        `max_step`."""
        return jnp.inf if self.max_step is None else self.max_step

    @abc.abstractmethod
    def valid(self) -> Bool[Array, ""]:
        """The motion's parameters in range (traceable)."""

    @property
    def least_gravity(self):
        """A lower bound of g_eff over the motion (m/s^2): g - max |a_v|, or
        the Python float `GRAVITY` without a vertical motion. Every level of
        a shortcut for a block at rest is scaled by least_gravity / g."""
        return GRAVITY

    def least_gravity_from(self, t):
        """A lower bound of g_eff from t on (m/s^2): `least_gravity`, or g
        once a vertical motion that ends before the horizontal one has
        ended (the level of the shortcuts for a block at rest, which an
        underestimate of g_eff lowers: steps then end where |x_g''| is near
        a level far below the block's)."""
        del t
        return self.least_gravity

    def level_from(self, level, t):
        """A block's rest level at g (`rest_level`, m/s^2) at the least g_eff
        from t on: times `least_gravity_from(t)` / g (the level itself
        without a vertical motion)."""
        least = self.least_gravity_from(t)
        if isinstance(least, float) and least == GRAVITY:
            return level
        return level * (least / GRAVITY)

    def gravity_bound(self, t0, t1):
        """A lower bound of g_eff over [t0, t1] (m/s^2; -inf when none is
        cheap): g plus a lower bound of a_v (the rest rule reads it)."""
        del t0, t1
        return GRAVITY

    @abc.abstractmethod
    def acceleration_bound(self, t0, t1) -> Float[Array, ""]:
        """A bound of |x_g''| over [t0, t1] (m/s^2), inf when none is cheap."""

    @abc.abstractmethod
    def limits_steps(self, resting: bool) -> bool:
        """Whether `next_kink` ends steps (static; see the class)."""

    @abc.abstractmethod
    def next_kink(self, t, quiet_below=None, quiet_end=None) -> Float[Array, ""]:
        """Where the step that starts at t must end (s; inf: anywhere), where
        `limits_steps`. `quiet_below` (m/s^2; a lane's own level, 0 for a
        rocking lane): a block at rest on a fixed base uplifts only where
        |x_g''| reaches it, so a step may end anywhere before |x_g''| could
        reach it and must end before it. `quiet_end`: a record's
        `quiet_end(t0, level)` of an earlier t0 <= t, read where
        `quiet_holds(t, quiet_end)` (None: search)."""

    @abc.abstractmethod
    def step_end(self, t0, dt, kink) -> Float[Array, ""]:
        """The end of a step of at most dt (s) from t0 that stops at `kink`
        (`next_kink`; inf: none)."""

    def step_accelerations(self, times):
        """x_g'' (m/s^2) at the times of one step of the flat loop of maps: its
        stage times and its end, within [t0, t1] (`times[0]` = t0,
        `times[-1]` = t1)."""
        return accelerations_at(self, times)

    def step_gravities(self, times):
        """g_eff (m/s^2) at the times of one step (`step_accelerations`)."""
        return gravities_at(self, times)


def accelerations_at(signal: AbstractAcceleration, times):
    """x_g'' (m/s^2) at any `times`, in one vectorized evaluation: one copy of
    a closed form in the program, not one a time."""
    return computed_once(jax.vmap(signal.acceleration)(jnp.stack(times)))


def gravities_at(signal: AbstractAcceleration, times):
    """g_eff (m/s^2) at any `times`, in one vectorized evaluation."""
    return computed_once(jax.vmap(signal.gravity)(jnp.stack(times)))


class _Negated(eqx.Module):
    """-a of a pulse, with a largest step (what `_below_level_until` reads)."""

    pulse: AbstractPulse
    max_step: Array

    def acceleration(self, t):
        return -self.pulse.acceleration(t)

    @property
    def end_time(self):
        return self.pulse.end_time


def _below_level_until(signal, t, quiet_below, curvature, start, one_sided=False):
    """The end of the step from t of a closed-form motion (see `next_kink`):
    with a = x_g''(t), a' its rate and |(x_g'')''| <= `curvature` (m/s^4, a
    bound), |x_g''(t + h)| <= |a| + |a'| h + curvature h^2 / 2, which stays
    below `quiet_below` for h < 2 m / (|a'| + sqrt(a'^2 + 2 curvature m)),
    m = quiet_below - |a|. Before `start`, where x_g'' begins with a kink,
    the step ends there. At least `max_step` / 1000: an excursion beyond the
    level by less than curvature (max_step / 1000)^2 / 2 may still hide.
    Where |x_g''| is at or above `quiet_below` already (a level lowered by
    the least g_eff of a vertical motion, below the block's own level
    now), the step ends `max_step` on, as any step while the ground moves:
    the uplift condition, at g_eff, is located on it."""
    a, rate = jax.jvp(signal.acceleration, (t,), (jnp.ones_like(t),))
    # (`one_sided`: a level of a itself, not of |a|.)
    margin = jnp.maximum(quiet_below - (a if one_sided else jnp.abs(a)), 0.0)
    root = jnp.sqrt(rate * rate + 2.0 * curvature * margin)
    h = 2.0 * margin / jnp.maximum(jnp.abs(rate) + root, jnp.finfo(t.dtype).tiny)
    h = jnp.where(margin > 0, jnp.maximum(h, 1e-3 * signal.max_step), signal.max_step)
    end = jnp.where(t < start, jnp.minimum(t + h, start), t + h)
    return jnp.where((quiet_below > 0) & (t < signal.end_time), end, jnp.inf)


class ClosedFormSignal(AbstractSignal):
    """A closed-form motion as the engines read it: x_g'' at any time, steps
    that end where the controller puts them, and, under an `AbstractPulse`,
    steps of a block at rest on a fixed base that end before |x_g''| could
    reach its uplift level (`_below_level_until`)."""

    motion: AbstractGroundMotion

    @property
    def _horizontal(self) -> AbstractGroundMotion:
        if isinstance(self.motion, WithVertical):
            return self.motion.horizontal
        return self.motion

    def acceleration(self, t):
        return self.motion.acceleration(t)

    def gravity(self, t):
        if not isinstance(self.motion, WithVertical):
            return GRAVITY
        return GRAVITY + self.motion.vertical_acceleration(t)

    @property
    def least_gravity(self):
        if not isinstance(self.motion, WithVertical):
            return GRAVITY
        return GRAVITY - self.motion.vertical.peak_acceleration_bound

    def least_gravity_from(self, t):
        if not isinstance(self.motion, WithVertical):
            return GRAVITY
        ended = t >= self.motion.vertical.end_time
        return jnp.where(ended, GRAVITY, self.least_gravity)

    def gravity_bound(self, t0, t1):
        if not isinstance(self.motion, WithVertical):
            return GRAVITY
        return GRAVITY + self.motion.vertical.acceleration_lower_bound(t0, t1)

    @property
    def end_time(self):
        return self.motion.end_time

    @property
    def max_step(self):
        return self.motion.max_step

    def valid(self):
        return self.motion.valid()

    def acceleration_bound(self, t0, t1):
        return self.motion.acceleration_bound(t0, t1)

    @property
    def _vertical_pulse(self) -> AbstractPulse | None:
        """The vertical part, where it is a pulse (bounded curvature)."""
        if isinstance(self.motion, WithVertical) and isinstance(
            self.motion.vertical, AbstractPulse
        ):
            return self.motion.vertical
        return None

    def limits_steps(self, resting: bool) -> bool:
        if self._vertical_pulse is not None:
            return True  # (steps end before g_eff could reach 0 unseen)
        return resting and isinstance(self._horizontal, AbstractPulse)

    def next_kink(self, t, quiet_below=None, quiet_end=None):
        del quiet_end
        end = jnp.inf
        if quiet_below is not None and isinstance(self._horizontal, AbstractPulse):
            curvature = self._horizontal.acceleration_curvature
            start = self._horizontal.start_time
            end = _below_level_until(self, t, quiet_below, curvature, start)
        vertical = self._vertical_pulse
        if vertical is not None:
            end = jnp.minimum(end, self._above_zero_until(t, vertical))
        return end

    def _above_zero_until(self, t, vertical: AbstractPulse):
        """The end of a step from t before which g_eff = g + a_v cannot reach
        0 (the free flight's condition, which would otherwise dip below 0
        and back inside one step unseen): `_below_level_until` of -a_v at
        the level g, with the vertical pulse's curvature, where the vertical
        part can reach -g at all (inf elsewhere, and once it has ended)."""
        flipped = _Negated(vertical, self.max_step)
        end = _below_level_until(
            flipped,
            t,
            jnp.asarray(GRAVITY, dtype=jnp.result_type(t, float)),
            vertical.acceleration_curvature,
            vertical.start_time,
            one_sided=True,
        )
        can_fly = vertical.peak_acceleration_bound >= GRAVITY
        return jnp.where(can_fly & (t < vertical.end_time), end, jnp.inf)

    def step_end(self, t0, dt, kink):
        # (The kink only bounds where a block at rest could uplift, and moves
        # with t0.)
        return jnp.minimum(t0 + dt, kink)


class RecordSignal(AbstractSignal):
    """A record (or a suite's row) as the engines read it: x_g'' linear
    between the samples, steps that end at the samples, and, with its tables,
    a block at rest that skips samples (`with_peaks`, `with_translation`).

    Inside a map under a suite, `row` gives the view of one record that reads
    the suite's arrays in place (`index`: the suite's record, batched over
    the lanes while the suite is not): the samples are never copied per lane.
    """

    record: Record
    # max |x_g''| of `record.unscaled` over sample ranges [k, k + 2^l)
    # (`with_peaks`), or None.
    peaks: Float[Array, "*records levels n"] | None = None
    # With a vertical part: max of -a_v (how far g_eff falls below g) over
    # the same ranges (`with_peaks`), or None.
    vertical_lows: Float[Array, "*records levels n"] | None = None
    # A linear isolator's response in translation to the unscaled records
    # (`with_translation`), or None.
    translation: TranslationTables | None = None
    # A suite's row view: the suite's record this one reads (`row`), else None.
    index: Int[Array, ""] | None = None

    def valid(self):
        return self.record.valid()

    def limits_steps(self, resting: bool) -> bool:
        return True

    @property
    def sample_count(self) -> int:
        return self.record.sample_count

    # -- reading the record (a suite's row in place) ----------------------------

    def _read(self, array, *at):
        """array[at] of `unscaled`, `peaks` or a table of `translation` of this
        record: of the suite's record `index` for a view (the factors' axes
        lead the batch)."""
        if self.index is None:
            return array[at]
        r = self.record
        row = self.index if r.factor is None else self.index % len(r.unscaled)
        return array[(row,) + at]

    def _of_batch(self, array):
        """This record's element of `dt`, `length` or `factor`."""
        return array if self.index is None else array[self.index]

    @property
    def _dt(self):
        return self._of_batch(self.record.dt)

    @property
    def _length(self):
        return self._of_batch(self.record.length)

    def _sample(self, k):
        """x_g'' at the samples k (m/s^2)."""
        a = self._read(self.record.unscaled, k)
        if self.record.factor is None:
            return a
        # Rounded as the product multiplied out (`Record.samples`) would be:
        # no rewrite of XLA's, f a1 - f a0 -> f (a1 - a0), reaches across.
        return computed_once(self._of_batch(self.record.factor) * a)

    def row(self, index) -> "RecordSignal":
        """Record `index` of the suite (its motion axes flattened, C order),
        as a view that reads the suite's arrays in place: what the lanes of a
        map under a suite take (`index` batched, the suite not)."""

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
        r = self.record
        return eqx.tree_at(
            lambda s: (
                s.record.unscaled,
                s.record.dt,
                s.record.length,
                s.record.factor,
                s.record.vertical,
                s.peaks,
                s.vertical_lows,
                s.translation,
                s.index,
            ),
            self,
            (
                flat(r.unscaled, 1),
                flat(r.dt),
                flat(r.length),
                flat(r.factor),
                flat(r.vertical, 1),
                flat(self.peaks, 2),
                flat(self.vertical_lows, 2),
                translation,
                jnp.asarray(index),
            ),
            is_leaf=lambda x: x is None,
        )

    def row_axes(self) -> "RecordSignal":
        """The `jax.vmap` in_axes of views from `row` with a lane axis: the
        index batched (0), the suite's arrays not (None)."""
        axes = jax.tree_util.tree_map(lambda _: None, self.row(0))
        return eqx.tree_at(lambda s: s.index, axes, 0, is_leaf=lambda x: x is None)

    # -- what the engines read ----------------------------------------------------

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

    @property
    def max_step(self):
        return None

    @property
    def step_bound(self):
        return self._dt  # (its steps end at the samples)

    def _vertical_view(self) -> "RecordSignal":
        """The vertical samples read as a record's (the same dt, length,
        factor and row), their table of lows (`vertical_lows`) as its peaks."""
        return eqx.tree_at(
            lambda s: (
                s.record.unscaled,
                s.record.vertical,
                s.peaks,
                s.vertical_lows,
                s.translation,
            ),
            self,
            (self.record.vertical, None, self.vertical_lows, None, None),
            is_leaf=lambda x: x is None,
        )

    def gravity(self, t):
        if self.record.vertical is None:
            return GRAVITY
        return GRAVITY + self._vertical_view().acceleration(t)

    def step_gravities(self, times):
        """g_eff at a step's times from two samples of the vertical part
        (`step_accelerations`' line)."""
        view = self._vertical_view()
        return [GRAVITY + a for a in view.step_accelerations(times)]

    def gravity_bound(self, t0, t1):
        if self.record.vertical is None:
            return GRAVITY
        return GRAVITY - self._vertical_view()._bound(t0, t1, jnp.negative)

    @property
    def least_gravity(self):
        if self.record.vertical is None:
            return GRAVITY
        peak = jnp.max(jnp.abs(self._read(self.record.vertical)), axis=-1)
        factor = self.record.factor
        if factor is not None:
            peak = peak * self._of_batch(factor)
        return GRAVITY - peak

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
        at most `_BOUND_SAMPLES` samples after t0; over a longer interval,
        from the table of peaks (inf without one)."""
        return self._bound(t0, t1, jnp.abs)

    def _bound(self, t0, t1, of):
        """max of of(x_g'') over [t0, t1] (`of`: abs, or negative with a
        table of the samples' negatives): `_extreme`, else `_peak_bound`."""
        near = self._extreme(t0, t1, of)
        if self.peaks is None:
            return near
        return jnp.where(jnp.isinf(near), self._peak_bound(t0, t1, of), near)

    def _peak_bound(self, t0, t1, of=jnp.abs):
        """max of(x_g'') over [t0, t1] from the table of peaks (of of(samples)):
        the samples strictly inside, [i, j], are the union of the two ranges
        of 2^l samples from i and to j (2^l <= j - i + 1 < 2^(l+1)), and the
        ends. (A factor > 0 scales of(samples) alike.)"""
        n, dt = self.sample_count, self._dt
        i = jnp.clip(jnp.floor(t0 / dt) + 1.0, 0, n - 1).astype(int)
        j = jnp.clip(jnp.ceil(t1 / dt) - 1.0, 0, n - 1).astype(int)
        count = jnp.maximum(j - i + 1, 1)
        width_log = jnp.floor(jnp.log2(1.0 * count)).astype(int)
        # (log2 rounded either way at a power of two)
        width_log = width_log + (2 ** (width_log + 1) <= count)
        width_log = width_log - (2**width_log > count)
        factor = self.record.factor
        scale = 1.0 if factor is None else self._of_batch(factor)
        first = self._read(self.peaks, width_log, i)
        last = self._read(self.peaks, width_log, jnp.maximum(j - 2**width_log + 1, 0))
        ends = jnp.maximum(of(self.acceleration(t0)), of(self.acceleration(t1)))
        return jnp.maximum(ends, scale * jnp.maximum(first, last))

    def _extreme(self, t0, t1, of):
        """max of of(x_g'') over [t0, t1] (`acceleration_bound` with `of`
        abs; with negative, minus the least x_g'')."""
        n = self.sample_count
        dt = self._dt
        width = min(_BOUND_SAMPLES, n)
        first = jnp.floor(t0 / dt) + 1.0  # the first sample after t0
        start = jnp.clip(first, 0, n - width).astype(int)
        index = start + jnp.arange(width)
        near = self._sample(index)
        inside = (index >= first) & (index * dt < t1) & (index < self._length)
        ends = jnp.maximum(of(self.acceleration(t0)), of(self.acceleration(t1)))
        bound = jnp.maximum(ends, jnp.max(jnp.where(inside, of(near), -jnp.inf)))
        covered = (t1 < (start + width) * dt) | (t0 > self.end_time)
        return jnp.where(covered, bound, jnp.inf)

    def with_peaks(self) -> "RecordSignal":
        """The signal with its table of peaks (`peaks`): max |x_g''| over every
        range of 2^l samples, l = 0, 1, ..., L - 1 (2^(L-1) >= n), so that
        `next_kink` finds the first sample above a level in L reads. Of a
        suite, one table a record, unless the tables would exceed
        `_PEAKS_BYTES` (a suite's resting blocks then step through its
        samples). Of a scaled record, the table of its unscaled samples.
        With a vertical part, its table of lows too (`vertical_lows`: max of
        -a_v over the same ranges), for the rest rule's bound of g_eff.
        Traceable."""
        level, vertical = jnp.abs(self.record.unscaled), self.record.vertical
        n = level.shape[-1]
        tables = 1 if vertical is None else 2
        if tables * level.size * _levels(n) * level.dtype.itemsize > _PEAKS_BYTES:
            return self
        lows = None if vertical is None else range_maxima(-vertical)
        return eqx.tree_at(
            lambda s: (s.peaks, s.vertical_lows),
            self,
            (range_maxima(level), lows),
            is_leaf=lambda x: x is None,
        )

    def with_translation(self, base) -> "RecordSignal":
        """The signal with `translation`: the tables of `base`'s response in
        translation (`_translation.py`; a `LinearIsolator`, one for every
        lane), None for other bases or where the tables would exceed
        `_PEAKS_BYTES`. Traceable.

        The tables are those of the samples with their factors multiplied out
        (a scaled record's map equals, to the bit, that of its samples
        multiplied out), unless a suite holds several factors per record (at
        many intensities): then they are those of `unscaled`, one a record,
        read times each factor (the same response, linear in the factor, to
        the last bits).
        """
        r = self.record
        n = self.sample_count
        per_factor = r.factor is not None and (
            r.batch_shape != np.shape(r.unscaled)[:-1]
        )
        # (Multiplied out as `samples` would be: no rewrite of XLA's reaches
        # across the product.)
        samples = r.unscaled if per_factor else computed_once(r.samples)
        if samples.size * (2 * _levels(n) + 3) * 8 > _PEAKS_BYTES:
            return self
        tables = base.translation_tables(samples, r.dt, r.length)
        if tables is not None:
            tables = dataclasses.replace(tables, scaled=not per_factor)
        return eqx.tree_at(
            lambda s: s.translation, self, tables, is_leaf=lambda x: x is None
        )

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
        factor = self.record.factor
        scale = 1.0 if factor is None else self._of_batch(factor)

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
        factor = self.record.factor
        if factor is None or self.translation.scaled:
            return 1.0
        return self._of_batch(factor)

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


# Samples `RecordSignal.acceleration_bound` reads at most.
_BOUND_SAMPLES = 16
# The largest table of peaks `RecordSignal.with_peaks` builds (bytes): 28
# records of 18,000 samples take 62 MB.
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
# steps to it (`RecordSignal.step_end`).
_EQUAL_STEPS = 8
