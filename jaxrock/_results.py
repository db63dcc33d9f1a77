"""What an analysis returns and the options it takes: outcomes, statuses,
event kinds, `Response`, `History` and `SolverOptions`."""

from enum import IntEnum

import diffrax
import equinox as eqx
import numpy as np
from jaxtyping import Array, Float, Int

from ._misc import (
    AbstractChecked,
    at_least_zero,
    greater_than_zero,
    is_count,
    parameter,
)


class Outcome(IntEnum):
    """Outcome of one analysis (the colours of a behavior map)."""

    NO_ROCKING = 0
    ROCKING = 1
    OVERTURNED = 2


class Status(IntEnum):
    """How an analysis ended. Anything but SUCCESS means the numbers are not final."""

    SUCCESS = 0
    MAX_STEPS = 1  # a segment hit the solver's step limit (`max_steps`)
    MAX_SEGMENTS = 2  # the loop hit `max_segments` before the end of the window
    # The step-size controller or the event root finder failed, or an event was
    # missed (the block rotated past pi / 2 without overturning).
    SOLVER_FAILED = 3
    # A parameter out of its range inside compiled code (a module built from
    # traced values, which the checks at construction cannot see); every float
    # result is NaN.
    INVALID_INPUT = 4


class EventKind(IntEnum):
    """What ended a segment (reported in `History.event_kinds`)."""

    END = 0
    UPLIFT = 1
    APEX = 2
    IMPACT = 3  # impact followed by re-uplift about the other corner
    REST = 4  # impact after which rocking ends (pure translation)
    OVERTURN = 5
    REVERSAL = 6  # theta' changed sign before reaching theta = 0 (or the guard)
    BASE_PEAK = 7  # a new maximum of |u| (z in closed form: any reversal of u')
    FAILURE = 8
    QUIET = 9  # ground still and too little energy left to uplift or move further


# The defaults of every analysis (`simulate`, maps, design): integrator
# tolerances, the step limit of a segment, the segment limit of an analysis
# and the rest rule.
RTOL, ATOL = 1e-8, 1e-10
MAX_STEPS, MAX_SEGMENTS = 16384, 2000
REST_TOLERANCE = 1e-6


def max_steps_for(motion, max_steps: int | None) -> int:
    """The step limit of a segment: `max_steps`, or by default `MAX_STEPS`
    raised for a long record to a power of two above 4 steps a sample (every
    sample is a step boundary: a segment in translation through a whole
    record takes one step a sample or more). A guard against runaway solves,
    never a limit a valid record reaches."""
    if max_steps is not None:
        return max_steps
    return max(MAX_STEPS, 1 << (4 * motion.sample_count).bit_length())


class SolverOptions(AbstractChecked):
    """Numerical options. Tolerances are traced (new values do not recompile);
    the solver, `step` being set or not, and the limits are static.

    `rtol`, `atol`: PID tolerances. `solver`: a Diffrax solver (default Tsit5).
    `step`: a fixed step (s) instead of the PID controller; events are then
    located at step ends only (no root find), the naive baseline of the
    work-precision study. `max_steps`: step limit of one segment.
    `max_segments`: limit on the segments (events) of one analysis.
    `rest_tolerance`: the rest rule against Zeno chattering: rocking ends at an
    impact when the rebound could lift the block by less than
    `rest_tolerance * alpha`, estimated as theta'+^2 / (2 p^2 sin alpha) (free
    rocking from theta = 0), or when e <= 0 (Eq. 2.13).
    """

    rtol: Float[Array, ""] = parameter("rtol", default=RTOL)
    atol: Float[Array, ""] = parameter("atol", default=ATOL)
    max_steps: int = eqx.field(default=MAX_STEPS, static=True)
    max_segments: int = eqx.field(default=MAX_SEGMENTS, static=True)
    rest_tolerance: Float[Array, ""] = parameter(
        "rest_tolerance", default=REST_TOLERANCE
    )
    solver: diffrax.AbstractSolver = eqx.field(
        default_factory=diffrax.Tsit5, static=True
    )
    step: Float[Array, ""] | None = None

    def __check_init__(self):
        for name in ("max_steps", "max_segments"):
            value = getattr(self, name)
            if not is_count(value) or value < 1:
                raise ValueError(f"`{name}` must be an integer >= 1, got {value!r}")

    def constraints(self):
        out = [
            greater_than_zero("rtol", self.rtol),
            greater_than_zero("atol", self.atol),
            at_least_zero("rest_tolerance", self.rest_tolerance),
        ]
        if self.step is not None:
            out.append(greater_than_zero("step", self.step))
        return out


class History(eqx.Module):
    """Time histories of one analysis (SI units), sampled and at every event."""

    t: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    u: np.ndarray
    u_dot: np.ndarray
    z: np.ndarray
    regime: np.ndarray  # 0 translation, +1 / -1 rocking about x = +b / -b
    ground_acceleration: np.ndarray
    event_times: np.ndarray
    event_kinds: tuple[str, ...]
    alpha: float  # the block's alpha (rad), to plot theta / alpha


class Response(eqx.Module):
    """Result of `simulate` (and, with leading axes, of a behavior map).

    outcome: `Outcome` code. max_rotation: max |theta| / alpha (pi / (2 alpha)
    when overturned). max_base_displacement: max |u| (m), 0 on a fixed base.
    impacts: number of impacts. uplift_time: first uplift (s), NaN if none.
    status: `Status` code. steps, segments: solver steps and loop segments.
    history: `History` with `history=True`, else None.
    """

    outcome: Int[Array, "..."]
    max_rotation: Float[Array, "..."]
    max_base_displacement: Float[Array, "..."]
    impacts: Int[Array, "..."]
    uplift_time: Float[Array, "..."]
    status: Int[Array, "..."]
    steps: Int[Array, "..."]
    segments: Int[Array, "..."]
    history: History | None = None

    @property
    def ok(self):
        return self.status == Status.SUCCESS

    def summary(self) -> str:
        """One line: outcome, max rotation, max base displacement, impacts."""
        if int(self.status) == Status.INVALID_INPUT:
            return (
                "INVALID_INPUT: a parameter of the block, base, motion or options "
                "is out of its range (built from traced values, so not checked "
                "when built); the results are NaN"
            )
        outcome = Outcome(int(self.outcome)).name
        uplift = float(self.uplift_time)
        text = (
            f"{outcome}: max|theta|/alpha = {float(self.max_rotation):.6g}, "
            f"max|u| = {float(self.max_base_displacement):.6g} m, "
            f"impacts = {int(self.impacts)}, uplift at "
            + ("never" if np.isnan(uplift) else f"{uplift:.6g} s")
        )
        if int(self.status) != Status.SUCCESS:
            text += f" [status {Status(int(self.status)).name}: not converged]"
        return text
