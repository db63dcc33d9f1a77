"""Vertical ground motion: a horizontal motion paired with the ground's
vertical acceleration a_v(t) (m/s^2, positive upward), which the block feels
as a change of gravity, g_eff(t) = g + a_v(t) (docs/model.md).

Two closed forms make a `WithVertical`; a record on either side makes a
`Record` whose `vertical` samples sit beside its horizontal ones (a closed
form sampled at the record's `dt`), so that suites, scale factors and the
maps' in-place reading of records carry the vertical part unchanged.
"""

import jax.numpy as jnp
import numpy as np

from ._ground import AbstractGroundMotion
from ._record import Record


class WithVertical(AbstractGroundMotion):
    """A closed-form horizontal motion with a closed-form vertical one
    (`AbstractGroundMotion.with_vertical`): x_g''(t) is the horizontal's,
    the excitation ends when both have ended, and steps are as short as
    either needs.

    Attributes:
        horizontal: the horizontal motion (m/s^2).
        vertical: the vertical acceleration a_v (m/s^2, positive upward).

    Examples:
        >>> import jaxrock as jr
        >>> pulse = jr.near_fault_pulse("San Fernando PCD/SN")
        >>> shaken = pulse.with_vertical(jr.SinePulse(amplitude=4.0, frequency=1.5))
        >>> type(shaken).__name__, round(float(shaken.end_time), 3)
        ('WithVertical', 2.353)
        >>> r = jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(), shaken)
        >>> jr.Outcome(int(r.outcome)).name
        'OVERTURNED'
    """

    horizontal: AbstractGroundMotion
    vertical: AbstractGroundMotion

    def __check_init__(self):
        # Built directly, as `with_vertical` builds it: two closed forms (a
        # record on either side makes a `Record`), the vertical one without
        # a vertical part of its own (which would be dropped unseen).
        for name, part in (
            ("horizontal", self.horizontal),
            ("vertical", self.vertical),
        ):
            if not isinstance(part, AbstractGroundMotion):
                raise ValueError(
                    f"`{name}` must be a closed-form ground motion (MPPulse or "
                    f"SinePulse), got {type(part).__name__}"
                )
            if isinstance(part, Record):
                raise ValueError(
                    f"`{name}` is a Record: pair a record with "
                    "`record.with_vertical(vertical)` (or "
                    "`pulse.with_vertical(record)`), which makes a Record with "
                    "its vertical samples"
                )
        if isinstance(self.vertical, WithVertical):
            raise ValueError(
                "`vertical` already has a vertical part (only its horizontal "
                "part would be read)"
            )

    def acceleration(self, t):
        return self.horizontal.acceleration(t)

    def vertical_acceleration(self, t):
        """a_v(t) (m/s^2, positive upward)."""
        return self.vertical.acceleration(t)

    @property
    def end_time(self):
        return jnp.maximum(self.horizontal.end_time, self.vertical.end_time)

    def acceleration_bound(self, t0, t1):
        return self.horizontal.acceleration_bound(t0, t1)

    @property
    def max_step(self):
        steps = [m.max_step for m in (self.horizontal, self.vertical)]
        steps = [s for s in steps if s is not None]
        if not steps:
            return None
        return steps[0] if len(steps) == 1 else jnp.minimum(*steps)

    def valid(self):
        return self.horizontal.valid() & self.vertical.valid()

    def names(self):
        return self.horizontal.names()

    def unlabeled(self):
        return WithVertical(self.horizontal.unlabeled(), self.vertical.unlabeled())

    def scaled(self, factor) -> "WithVertical":
        """Both parts times `factor` (> 0; an array adds leading axes)."""
        return WithVertical(
            self.horizontal.scaled(factor), self.vertical.scaled(factor)
        )

    def describe(self):
        return f"{self.horizontal.describe()} with vertical {self.vertical.describe()}"


def _sampled(motion: AbstractGroundMotion, dt, n) -> np.ndarray:
    """A closed form's acceleration at k dt, k < n (m/s^2)."""
    return np.asarray(motion.acceleration(jnp.arange(n) * dt))


def _samples_for(motion: AbstractGroundMotion, dt: float) -> int:
    """Samples of dt that cover a closed form's excitation."""
    return int(np.ceil(float(np.max(motion.end_time)) / dt)) + 2


def _one(name: str, motion: AbstractGroundMotion) -> None:
    """`ValueError` unless `motion` is one unscaled motion without a vertical
    part (a `with_vertical` pairs one horizontal with one vertical)."""
    if not isinstance(motion, AbstractGroundMotion):
        raise ValueError(
            f"`{name}` must be a ground motion (MPPulse, SinePulse or Record), got "
            f"{type(motion).__name__}"
        )
    if (
        isinstance(motion, WithVertical)
        or getattr(motion, "vertical", None) is not None
    ):
        raise ValueError(f"`{name}` already has a vertical part")
    if motion.batch_shape:
        raise ValueError(
            f"`{name}` must be one motion, not a batch of shape {motion.batch_shape}: "
            "pair each record with its vertical, then `Record.stack` them"
        )
    if isinstance(motion, Record) and motion.factor is not None:
        raise ValueError(
            f"`{name}` is a scaled record: pair the records first, then scale "
            "(a scale factor applies to both parts)"
        )


def with_vertical(horizontal, vertical) -> AbstractGroundMotion:
    """`horizontal` with `vertical` (see `AbstractGroundMotion.with_vertical`)."""
    _one("horizontal motion", horizontal)
    _one("vertical", vertical)
    records = [m for m in (horizontal, vertical) if isinstance(m, Record)]
    if not records:
        return WithVertical(horizontal, vertical)
    dt = float(records[0].dt)
    if len(records) == 2 and float(vertical.dt) != dt:
        raise ValueError(
            f"`vertical` must share the record's time step, dt = {dt:g} s, got "
            f"{float(vertical.dt):g} s: resample one of them"
        )

    def samples(motion):
        if isinstance(motion, Record):
            return np.asarray(motion.samples)[: int(motion.length)]
        return _sampled(motion, dt, _samples_for(motion, dt))

    parts = [samples(m) for m in (horizontal, vertical)]
    n = max(p.size for p in parts)
    h, v = (np.pad(p, (0, n - p.size)) for p in parts)
    labels = records[0].labels() if isinstance(horizontal, Record) else {}
    return Record(h, dt, vertical=v, **labels)
