"""What an analysis returns and the options it takes: outcomes, statuses,
event kinds, `Response`, `History` and `SolverOptions`."""

from enum import IntEnum

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ._misc import (
    AbstractChecked,
    greater_than_zero,
    in_range,
    is_count,
    one_real_number,
    parameter,
    positive,
)
from ._scene import sample_count


class Outcome(IntEnum):
    """The outcome of one analysis: the colours of a behavior map.

    `Response.outcome` and the maps hold these codes as integers;
    `Outcome(code).name` names one.

    Attributes:
        NO_ROCKING: the block never uplifts; it moves with its base (0).
        ROCKING: the block uplifts at least once and does not overturn (1).
        OVERTURNED: the block overturns: |theta| reaches pi / 2 rad (2).

    Examples:
        >>> import jaxrock as jr
        >>> jr.Outcome(2).name, int(jr.Outcome.ROCKING)
        ('OVERTURNED', 1)
    """

    NO_ROCKING = 0
    ROCKING = 1
    OVERTURNED = 2


class Status(IntEnum):
    """How an analysis ended: anything but SUCCESS means the numbers are not final.

    `Response.status` and the maps hold these codes as integers;
    `Status(code).name` names one. A module built from concrete values that
    are out of range raises `ValueError` at once; one built from traced
    values (inside `jax.jit`, `jax.vmap` or `jax.jacfwd`) cannot be checked
    then, and its analysis ends with INVALID_INPUT.

    Attributes:
        SUCCESS: the analysis reached its end: an overturn, a state from which
            nothing more can happen, a block that can no longer overturn
            (on a fixed base once the ground is still, free rocking below
            the separatrix), or the end of a window the user set
            (`duration`, s) (0).
        MAX_STEPS: a segment hit the solver's step limit, `max_steps` (1).
        MAX_SEGMENTS: the analysis hit `max_segments` before its end (2).
        SOLVER_FAILED: the step-size controller or the event root finder
            failed, or an event was missed: |theta| passed pi / 2 rad without
            an overturn (3).
        INVALID_INPUT: a parameter out of its range in a module built from
            traced values, which the checks at construction cannot see; the
            float results (max_rotation, max_base_displacement, uplift_time)
            are NaN (4).
        UNDECIDED: an analysis run until the block's fate is decided (the
            default `duration`) reached `DECISION_WINDOW` s after the
            excitation with the block still able to uplift, rock on or
            overturn (5).
        SLIDING: the block has a `friction` mu, and at some time the
            horizontal force that holds it exceeded mu times the normal
            force (in translation, rocking before it passes its corner's
            vertical, or at an impact): it would slide, which the model does
            not follow; the results are those of the model without sliding
            (6). A failure above takes precedence.
        FREE_FLIGHT: under vertical ground motion, g + a_v(t) reached 0: the
            ground fell faster than gravity and the block would leave its
            base in free flight, which the model does not follow; the
            analysis stops there, its results those up to then (7).
        CAPACITY_EXCEEDED: the isolator has a `capacity` without a `stop`
            and max |u| reached it: the base would hit its stop, which the
            model then does not follow;
            the results are those of the isolator without a stop (8). Also
            where max |u| reached the isolator's `geometric_limit` (a
            friction pendulum's radius R), stop or not. It takes precedence
            over SLIDING; a failure over both.

    Examples:
        >>> import jaxrock as jr
        >>> jr.Status(3).name, int(jr.Status.INVALID_INPUT)
        ('SOLVER_FAILED', 4)
    """

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
    # Run until decided, the block's fate still open at the window's end.
    UNDECIDED = 5
    # The friction needed to hold the block exceeded its `friction`.
    SLIDING = 6
    # The ground fell faster than gravity: the block would leave its base.
    FREE_FLIGHT = 7
    # The isolator's displacement reached its `capacity`.
    CAPACITY_EXCEEDED = 8


class EventKind(IntEnum):
    """What ended a segment of an analysis: the events of a `History`.

    An analysis is a sequence of segments, each integrated until an event.
    `History.event_kinds` holds the events' names in lower case ("uplift",
    "impact", ...); END, the end of the window, is not listed there.

    Attributes:
        END: the segment reached the end of the window (`duration`, s).
        UPLIFT: the block uplifts: the absolute base acceleration
            |u'' + x_g''| reaches g tan(alpha) (m/s^2).
        APEX: theta' = 0 rad/s while |theta| grows: the block turns back.
        IMPACT: theta = 0 rad while falling: an impact, then re-uplift about
            the other corner.
        REST: an impact after which rocking ends (the rest rule of
            `SolverOptions`): the block moves with its base again.
        OVERTURN: |theta| reaches pi / 2 rad.
        REVERSAL: theta' changes sign before theta reaches 0 (the block
            rises again about the same corner).
        BASE_PEAK: a new maximum of |u| (m) of an isolated base (with z in
            closed form, any reversal of u').
        FAILURE: the segment's solve failed (see `Status`).
        QUIET: the ground is still and the energy left can neither uplift the
            block nor raise max |u|: the analysis ends early.
        SLIDE: the friction needed to hold a block with a `friction` reaches
            its own (`Status.SLIDING`); the analysis goes on without sliding.
        FLIGHT: g + a_v(t) reaches 0 under vertical ground motion
            (`Status.FREE_FLIGHT`); the analysis ends.
        STOP: the base meets its `Stop` (|u| reaches the isolator's
            capacity) or leaves it.
        CORNER: a block with a `friction` passes its corner's vertical
            (|theta| = alpha), past which it falls over and its friction is
            not checked, or comes back over it.

    Examples:
        >>> import jaxrock as jr
        >>> jr.EventKind(3).name.lower(), int(jr.EventKind.OVERTURN)
        ('impact', 5)
    """

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
    SLIDE = 10  # the friction needed to hold the block reaches its own
    FLIGHT = 11  # g + a_v reaches 0: the block would leave its base
    STOP = 12  # the base meets or leaves its stop
    CORNER = 13  # a block with a friction passes its corner's vertical, either way


# The defaults of every analysis (`simulate`, maps, design): integrator
# tolerances, the step limit of a segment, the segment limit of an analysis
# and the rest rule.
RTOL, ATOL = 1e-8, 1e-10
MAX_STEPS, MAX_SEGMENTS = 16384, 2000
REST_TOLERANCE = 1e-6
# Without a `duration`, an analysis runs until the block's fate is decided, for
# at most this long after the excitation (s).
DECISION_WINDOW = 60.0


def _max_steps_for(motion, max_steps: int | None) -> int:
    """The step limit of a segment: `max_steps`, or by default `MAX_STEPS`
    raised for a long record to a power of two above 4 steps a sample (every
    sample is a step boundary: a segment in translation through a whole
    record takes one step a sample or more). A guard against runaway solves,
    never a limit a valid record reaches."""
    if max_steps is not None:
        return max_steps
    return max(MAX_STEPS, 1 << (4 * sample_count(motion)).bit_length())


def _flag(x):
    """A bool array leaf: NumPy's for a concrete value (a JAX array built
    outside compiled code compiles a program of its own)."""
    if isinstance(x, jax.core.Tracer):
        return jnp.asarray(x, dtype=bool)
    return np.asarray(x, dtype=bool)


def analysis_window(motion, duration):
    """(duration, until_decided): a window the user set (s), or for None the
    end of the excitation plus `DECISION_WINDOW`, run until the block's fate
    is decided. A concrete end stays in NumPy (an operation on a concrete JAX
    array compiles a program of its own)."""
    if duration is not None:
        return duration, False
    end = motion.end_time  # the latest of a batch
    if isinstance(end, jax.core.Tracer):
        return jnp.max(end) + DECISION_WINDOW, True
    return np.max(np.asarray(end)) + DECISION_WINDOW, True


class SolverOptions(AbstractChecked):
    """The numerical options of an analysis.

    `simulate` and `behavior_map` build one from their keywords;
    `jaxrock.design.responses` and `jaxrock.design.isolator_objective` take
    one. The tolerances are traced (new values do not recompile); the solver,
    whether `step` is set, and the limits are static. The rest rule, against
    Zeno chattering, ends rocking at an impact when the coefficient of
    restitution e = theta'+ / theta'- of the impact is <= 0 (Eq. 2.13 of the
    paper), or when the rebound could lift the block by less than
    `rest_tolerance` alpha (rad), estimated as theta'+^2 / (2 p^2 sin alpha)
    from the velocity theta'+ (rad/s) after the impact (free rocking from
    theta = 0, linearized).

    Args:
        rtol: the relative tolerance of the step-size controller (-),
            > 0; default 1e-8.
        atol: the absolute tolerance (in the state's units: rad, rad/s, m,
            m/s), > 0; default 1e-10.
        max_steps: the step limit of one segment, an integer >= 1; default
            16384.
        max_segments: the limit on the segments (events) of one analysis, an
            integer >= 1; default 2000.
        rest_tolerance: the rest rule's threshold, a fraction of alpha (-),
            in [0, 0.01]; default 1e-6.
        solver: an adaptive Diffrax solver of one ODE term (an instance);
            default `diffrax.Tsit5()`.
        step: a fixed step (s), > 0, instead of the step-size controller;
            events are then located at step ends only (no root find), a
            naive baseline for comparisons. Default None.

    Raises:
        ValueError: a concrete tolerance or step out of its range, a limit
            that is not an integer >= 1, or a `solver` that is not an
            adaptive Diffrax solver (the message names it).

    Examples:
        >>> import jaxrock as jr
        >>> opts = jr.SolverOptions(rtol=1e-6, atol=1e-8)
        >>> float(opts.rtol), opts.max_steps, opts.max_segments
        (1e-06, 16384, 2000)
        >>> jr.SolverOptions(max_segments=0)
        Traceback (most recent call last):
        ...
        ValueError: `max_segments` must be an integer >= 1, got 0
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
    # The window is the limit of an analysis run until the block's fate is
    # decided (`DECISION_WINDOW`): one that reaches it undecided is UNDECIDED.
    until_decided: Bool[Array, ""] = eqx.field(default=False, converter=_flag)

    def __check_init__(self):
        # One number each: the error norm would broadcast an array over the
        # state, and the rest rule over the lanes.
        limits = {"rtol": "> 0", "atol": "> 0", "rest_tolerance": "in [0, 0.01]"}
        for name, allowed in limits.items():
            one_real_number(name, getattr(self, name), allowed)
        for name in ("max_steps", "max_segments"):
            value = getattr(self, name)
            if not is_count(value) or value < 1:
                raise ValueError(f"`{name}` must be an integer >= 1, got {value!r}")
        # The step-size controller reads the solver's error estimate, and the
        # equations are one ODE term.
        solver = self.solver
        if not (
            isinstance(solver, diffrax.AbstractAdaptiveSolver)
            and solver.term_structure is diffrax.AbstractTerm
        ):
            raise ValueError(
                "`solver` must be an adaptive Diffrax solver of one ODE term, an "
                "instance such as diffrax.Tsit5(), diffrax.Dopri8() or "
                f"diffrax.Kvaerno5(), got {solver!r}"
            )

    def constraints(self):
        out = [
            greater_than_zero("rtol", self.rtol),
            greater_than_zero("atol", self.atol),
            # A rebound above 1% of alpha is rocking, not chatter: larger
            # values call blocks at rest that rock on (and change outcomes).
            in_range("rest_tolerance", self.rest_tolerance, 0.0, 0.01),
        ]
        if self.step is not None:
            out.append(greater_than_zero("step", self.step))
        return out

    @classmethod
    def for_motion(
        cls,
        motion,
        rtol,
        atol,
        max_steps,
        max_segments,
        rest_tolerance,
        solver,
        until_decided=False,
    ) -> "SolverOptions":
        """The options of an analysis under `motion`: `max_steps` None picks
        the step limit for its length (`_max_steps_for`), `solver` None Tsit5."""
        return cls(
            rtol,
            atol,
            _max_steps_for(motion, max_steps),
            max_segments,
            rest_tolerance,
            solver or diffrax.Tsit5(),
            until_decided=until_decided,
        )

    @classmethod
    def for_analysis(cls, motion, duration, **options) -> tuple:
        """(duration, options) of an analysis under `motion`: the window
        (`analysis_window`: None runs until decided), checked as one number
        > 0, and `for_motion`'s options from the keywords `rtol`, `atol`,
        `max_steps`, `max_segments`, `rest_tolerance` and `solver`."""
        duration, until_decided = analysis_window(motion, duration)
        duration = one_real_number("duration", duration, "finite and > 0 (s)")
        positive("duration", duration)
        return duration, cls.for_motion(motion, **options, until_decided=until_decided)


class History(eqx.Module):
    """The time histories of one analysis, from `simulate(..., history=True)`.

    Rows are sampled every `history_step` (s) and at every event; at an event
    two rows share its time, the state just before the transition and the
    state just after it. Every array but `event_times` holds one value per
    row (NumPy arrays).

    Attributes:
        t: the time (s).
        theta: the block's rotation (rad): > 0 rocking about the corner at
            x = +b, < 0 about the corner at x = -b.
        theta_dot: theta' (rad/s).
        u: the base's displacement relative to the ground (m); 0 on a fixed
            base.
        u_dot: u' (m/s).
        z: the Bouc-Wen variable of a friction pendulum (-); 0 on other bases.
        regime: 0 in translation, +1 or -1 rocking about the corner at x = +b
            or x = -b.
        ground_acceleration: x_g''(t) (m/s^2).
        event_times: the times of the events (s), one per event.
        event_kinds: the events' `EventKind` names in lower case ("uplift",
            "apex", "impact", ...), one per event.
        alpha: the block's alpha (rad), to plot theta / alpha.

    Examples:
        >>> import jaxrock as jr
        >>> r = jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(),
        ...                 jr.near_fault_pulse("San Fernando PCD/SN"), history=True)
        >>> r.history.event_kinds
        ('uplift', 'apex', 'impact', 'overturn')
        >>> r.history.event_times.round(2)
        array([0.72, 1.33, 1.58, 2.68])
    """

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


# The per-analysis numbers of a `Response` (a map holds one of each per cell).
RESPONSE_FIELDS = (
    "outcome",
    "max_rotation",
    "max_base_displacement",
    "impacts",
    "uplift_time",
    "status",
    "steps",
    "segments",
)


class Response(eqx.Module):
    """The result of one analysis (`simulate`), or of a batch of analyses.

    Scalars (0-d arrays) for `simulate`; arrays with the batch's leading axes
    under `jax.vmap` or from `jaxrock.design.responses`. Read `status` first:
    anything but `Status.SUCCESS` means the numbers are not final.

    Attributes:
        outcome: the `Outcome` code.
        max_rotation: max |theta| / alpha (-), pi / (2 alpha) when the block
            overturns.
        max_base_displacement: max |u| (m), the base's peak displacement
            relative to the ground; 0 on a fixed base.
        impacts: the number of impacts, that after which rocking ends
            included.
        uplift_time: the time of the first uplift (s); NaN if none.
        status: the `Status` code.
        steps: the solver's steps over all segments.
        segments: the segments of the analysis (one per event).
        history: a `History` with `simulate(..., history=True)`, else None.

    Examples:
        >>> import jaxrock as jr
        >>> r = jr.simulate(jr.Block(6.0, 1.0), jr.FixedBase(),
        ...                 jr.near_fault_pulse("Northridge JFA/SN"))
        >>> jr.Status(int(r.status)).name, jr.Outcome(int(r.outcome)).name
        ('SUCCESS', 'ROCKING')
        >>> round(float(r.max_rotation), 3), round(float(r.uplift_time), 3)
        (0.165, 3.228)
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
        """Whether the analysis succeeded: `status == Status.SUCCESS` (a bool array).

        Of a batch, one value per analysis.

        Examples:
            >>> import jaxrock as jr
            >>> r = jr.simulate(jr.Block(6.0, 1.0), jr.FixedBase(),
            ...                 jr.near_fault_pulse("Northridge JFA/SN"))
            >>> bool(r.ok)
            True
        """
        return self.status == Status.SUCCESS

    def summary(self) -> str:
        """One line: the outcome, max |theta| / alpha, max |u|, impacts, first uplift.

        Of one analysis (scalar fields). Lengths are in m and times in s; a
        status other than SUCCESS is flagged as not converged, and
        INVALID_INPUT explained.

        Returns:
            The line, a str.

        Examples:
            >>> import jaxrock as jr
            >>> r = jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(),
            ...                 jr.near_fault_pulse("San Fernando PCD/SN"))
            >>> print(r.summary())  # doctest: +NORMALIZE_WHITESPACE
            OVERTURNED: max|theta|/alpha = 6.41197, max|u| = 0 m, impacts = 1,
            uplift at 0.715262 s
        """
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
        if int(self.status) == Status.SLIDING:
            text += " [status SLIDING: the block would slide on its base]"
        elif int(self.status) == Status.FREE_FLIGHT:
            text += " [status FREE_FLIGHT: the block would leave its base]"
        elif int(self.status) == Status.CAPACITY_EXCEEDED:
            text += (
                " [status CAPACITY_EXCEEDED: the base would hit its stop or "
                "leave its dish]"
            )
        elif int(self.status) == Status.UNDECIDED:
            text += " [status UNDECIDED: the fate is still open at the window's end]"
        elif int(self.status) != Status.SUCCESS:
            text += f" [status {Status(int(self.status)).name}: not converged]"
        return text
