"""The prepared scene: what the engines may exploit about one base and motion,
decided once, before an analysis's loop.

The engines never ask a user's motion or isolator what they support. They
read a signal (`_signal.py`) that `prepare` builds from the motion, with the
tables of the shortcuts that apply under it, and ask this module the facts
about the scene that choose a code path:

- `fixed_base`: the base never moves (`FixedBase`). A block at rest on it
  uplifts only where |x_g''| reaches its level, so its steps may skip to
  there (`_model.quiet_level`); only the uplift conditions read the ground.
- `closed_form_tail`: free rocking once the ground is still has a closed
  form (`_free.py`), and a map finishes it without steps (unless the block's
  sliding is checked).
- `rocking_reads_all`: the conditions of a rocking block read the ground and
  the base's force (a block whose sliding is checked).
- `has_vertical`: the ground moves vertically too; g_eff = g + a_v(t) then
  enters the equations, the uplift level and a `weight_borne` isolator's
  force, and every shortcut for a block at rest uses its level at the least
  g_eff from its time on (`AbstractSignal.least_gravity_from`).
- `carries_quiet_end`: under a record, a block at rest on a fixed base
  skips samples to its next possible uplift, found in the record's table of
  peaks and carried from step to step.
- `rest_jumps`: a block at rest on a linear isolator under a record skips
  samples on the base's tabulated response (`_flat._rest_jump`).
- `carries_conditions`: a base with a hysteretic state, whose event
  conditions are costly: the flat loop carries their values from one step
  to the next (`Carry.start_conditions`).
- `MotionLayout`: how a map's cells hold their motion.

Adding a motion: a subclass of `AbstractGroundMotion` (a closed form, read
through `ClosedFormSignal`; an `AbstractPulse` adds the resting skip).
Adding an isolator: its own module; if it brings a shortcut, a fact here.
"""

import enum

from ._block import Block
from ._isolators import AbstractIsolator, FixedBase
from ._record import Record
from ._signal import AbstractSignal, ClosedFormSignal, RecordSignal, StillGround
from ._vertical import WithVertical


def prepare(motion, base: AbstractIsolator | None = None) -> AbstractSignal:
    """The signal the engines read of `motion`: a record's with its table of
    peaks and, for `base` (the base of every lane, or None), the base's
    translation tables; a closed form's wrapper. A signal is returned as it
    is (already prepared, or a suite's row view). Traceable."""
    if isinstance(motion, AbstractSignal):
        return motion
    if isinstance(motion, Record):
        signal = RecordSignal(motion.unlabeled()).with_peaks()
        if base is not None and base.stop is None:  # (tables of a free base)
            signal = signal.with_translation(base)
        return signal
    return ClosedFormSignal(motion.unlabeled())


def fixed_base(base: AbstractIsolator) -> bool:
    """The base never moves (static)."""
    return isinstance(base, FixedBase)


def closed_form_tail(block: Block, base: AbstractIsolator) -> bool:
    """A map finishes a rocking block's free rocking once the ground is still
    in closed form (static): the base answers (`free_rocking_closed_form`),
    for a block without a `friction` (the closed form skips the forces that
    hold the block)."""
    return base.free_rocking_closed_form and block.friction is None


def rocking_reads_all(block: Block) -> bool:
    """The event conditions of a rocking block read the ground's acceleration
    and the base's force (static): a block with a `friction`, whose slide
    condition reads both (`_events.condition_slide`)."""
    return block.friction is not None


def has_vertical(signal: AbstractSignal) -> bool:
    """The ground moves vertically too (static): a closed form `WithVertical`
    or a record with `vertical` samples (also as the `StillGround` of a map's
    rocking lanes, whose free flight is an event)."""
    if isinstance(signal, StillGround):
        return signal.vertical is not None and has_vertical(signal.vertical)
    if isinstance(signal, ClosedFormSignal):
        return isinstance(signal.motion, WithVertical)
    if isinstance(signal, RecordSignal):
        return signal.record.vertical is not None
    return False


def carries_quiet_end(base: AbstractIsolator, signal: AbstractSignal) -> bool:
    """A block at rest on the base skips to just before the next sample where
    |x_g''| may reach its uplift level, found from a table and carried
    between steps (static): a fixed base under a record's signal with its
    table of peaks (`Carry.quiet_end`)."""
    return (
        fixed_base(base)
        and isinstance(signal, RecordSignal)
        and signal.peaks is not None
    )


def rest_jumps(signal: AbstractSignal) -> bool:
    """Lanes at rest on the base skip samples on its tabulated response in
    translation (static): a record's signal with translation tables."""
    return isinstance(signal, RecordSignal) and signal.translation is not None


def carries_conditions(base: AbstractIsolator) -> bool:
    """The flat loop carries the event conditions' values between steps
    (static): a base with a hysteretic state."""
    return base.hysteretic_state


def sample_count(motion) -> int:
    """Samples of a recorded motion (0 for a closed form)."""
    if isinstance(motion, (Record, RecordSignal)):
        return motion.sample_count
    return 0


class MotionLayout(enum.Enum):
    """How the cells of a map hold their motion."""

    # The motion's parameters carry the cell axis (closed forms, batched).
    PER_CELL = "per cell"
    # One record of every cell, read in place.
    ONE_RECORD = "one record"
    # A suite of records: each cell an index into it, read in place.
    SUITE = "suite"

    @classmethod
    def of(cls, motion) -> "MotionLayout":
        if not isinstance(motion, Record):
            return cls.PER_CELL
        return cls.SUITE if motion.batch_shape else cls.ONE_RECORD
