"""Fragility: probability of rocking and of overturning against an intensity
measure, over an ensemble of motions, with lognormal fits by maximum likelihood."""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import log_ndtr
from jax.scipy.stats import norm

from ._ground import AbstractGroundMotion
from ._intensity import intensity_measure, measure_attrs, parse_measure
from ._isolators import AbstractIsolator, FixedBase
from ._labeled import ATTRS, Coordinates, coordinates, dataset
from ._maps import behavior_map
from ._misc import (
    grid_axis,
    is_count,
    one_block_options,
    one_real_number,
    positive,
    scale_factors,
    unbatched,
)
from ._model import check_base_and_motion
from ._record import Record
from ._results import Outcome, Status


def fit_lognormal(im, failed, *, trials=None):
    """Maximum-likelihood lognormal fit, P(failure | IM) = Phi(ln(IM / median) / beta).

    Phi is the standard normal distribution function, the median is in the
    units of the intensity measure IM (e.g. m/s^2 for a PGA) and beta (-) is
    the standard deviation of ln IM. With z = s ln IM - c (s = 1 / beta,
    c = ln(median) / beta) the log-likelihood

        sum_i k_i ln Phi(z_i) + (n_i - k_i) ln Phi(-z_i)

    (k_i failures of n_i analyses at IM_i: n_i = 1 for binary outcomes, the
    binomial form of a multiple-stripe analysis otherwise, Baker 2015) is
    concave in (c, s). Newton's method with a backtracking line search
    solves its score equations to convergence (a step below 1e-13 in
    standardized ln IM), in one compiled call.

    Separated outcomes have no maximum-likelihood fit: when
    a = max{IM : not failed} <= b = min{IM : failed}, as is usual for one
    motion scaled up until the block rocks, the likelihood approaches its
    supremum only as beta -> 0 (with the median strictly between a and b, or
    at a = b when they are equal). The fit is then that limit, a step:
    median = sqrt(a b), the middle of the gap on the log scale, and beta = 0,
    so that P(failure | IM) is 0 below the median, 1 above it and 1/2 at it
    (`Fragility.probability`). The data place the median only somewhere
    between a and b.

    Outcomes whose failures do not lean to larger IM have no increasing fit
    either. At s = 0, with c at its best, the slope of the log-likelihood in
    s is proportional to sum_i ln IM_i (k_i - f n_i), f the share of
    failures. When the mean of ln IM over the failures is at most that over
    the others (e.g. every failure below every non-failure, or one IM for
    all) that slope is <= 0: the supremum is approached as beta -> infinity,
    at the constant P(failure | IM) = f, a limit with no finite median. Both
    are NaN then.

    Args:
        im: the intensity measure of each analysis, or of each level with
            `trials` (any unit), a 1-D array of values > 0.
        failed: whether each analysis failed (bool, or 0 and 1), a 1-D array
            of the same length; with `trials`, the number of failures at each
            level (integers from 0 to `trials`).
        trials: None (binary outcomes), or the number of analyses at each
            level (integers >= 1; one number, or one per level): the binomial
            likelihood of a multiple-stripe analysis.

    Returns:
        (median, beta) as floats; (sqrt(a b), 0.0) when the outcomes are
        separated (above); both NaN when every or no analysis failed, or
        when the failures do not lean to larger IM (the likelihood has no
        maximum then, nor a step to tend to).

    Raises:
        ValueError: `im` and `failed` that are not 1-D arrays of one length,
            an `im` that is not finite and > 0, or counts that are not whole
            numbers with 0 <= failed <= trials and trials >= 1.

    Examples:
        >>> import jaxrock as jr
        >>> im = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0]  # PGA (m/s^2)
        >>> failed = [False, False, True, False, True, False, True, True]
        >>> median, beta = jr.fit_lognormal(im, failed)
        >>> round(median, 4), round(beta, 4)
        (2.0048, 0.6845)
        >>> levels = [0.2, 0.4, 0.6, 0.8]  # Sa(1 s) in g, 10 records each
        >>> median, beta = jr.fit_lognormal(levels, [0, 3, 6, 9], trials=10)
        >>> round(median, 4), round(beta, 4)
        (0.5134, 0.3784)
    """
    im = np.asarray(im, dtype=float)
    failed = np.asarray(failed)
    if im.ndim != 1 or failed.shape != im.shape:
        raise ValueError(
            "`im` and `failed` must be 1-D arrays of one length, got shapes "
            f"{im.shape} and {failed.shape}"
        )
    positive("im", im)
    if trials is None:
        count, total = _binary(failed), np.ones_like(im)
    else:
        count, total = _binomial(failed, trials, im.size)
    return _fit_counts(np.log(im), count, total)


def _binary(failed) -> np.ndarray:
    """`fit_lognormal`'s binary outcomes as counts of 0 and 1 (`ValueError`
    for anything else, NaN included)."""
    count = np.asarray(failed, dtype=float)
    bad = (count != 0) & (count != 1)
    if bad.any():
        raise ValueError(
            "`failed` must be booleans (or 0 and 1) without `trials`, got "
            f"{count[bad][:3].tolist()}"
        )
    return count


def _binomial(failed, trials, levels: int):
    """`fit_lognormal`'s failures and trials of each of `levels` levels, as
    floats (`ValueError` naming the one out of range)."""
    if np.shape(trials) not in ((), (levels,)):
        raise ValueError(
            "`trials` must be one number or one per level of `im`, got shape "
            f"{np.shape(trials)} for {levels} levels"
        )
    total = np.broadcast_to(np.asarray(trials, dtype=float), (levels,))
    count = np.asarray(failed, dtype=float)
    if not np.all((total >= 1) & (total == np.round(total))):
        raise ValueError(
            f"`trials` must be whole numbers >= 1, got {np.unique(total).tolist()}"
        )
    bad = ~((count >= 0) & (count <= total) & (count == np.round(count)))
    if bad.any():
        raise ValueError(
            "`failed` must count the failures of each level, whole numbers "
            f"from 0 to `trials`, got {count[bad].tolist()}"
        )
    return count, total


def _fit_counts(log_im, count, total):
    """(median, beta) of k = `count` failures of n = `total` analyses at
    each ln IM: the limits of `fit_lognormal` where there is no maximum, else
    Newton's solution."""
    passed = total - count
    if not count.any() or not passed.any():
        return float("nan"), float("nan")
    mean_failed = np.sum(count * log_im) / count.sum()
    mean_passed = np.sum(passed * log_im) / passed.sum()
    if mean_failed <= mean_passed:  # no increasing fit
        return float("nan"), float("nan")
    below, above = log_im[passed > 0].max(), log_im[count > 0].min()
    if below <= above:  # separated: the limit beta -> 0, a step
        return float(np.exp(0.5 * (below + above))), 0.0
    # Standardized ln IM keeps Newton's matrix well scaled; padded to a power
    # of two (weights 0) so that fits of many sizes share a few programs.
    center = np.sum(total * log_im) / total.sum()
    spread = np.sqrt(np.sum(total * (log_im - center) ** 2) / total.sum())
    size = 1 << max(3, (log_im.size - 1).bit_length())
    pad = (0, size - log_im.size)
    x, k, n = (np.pad(v, pad) for v in ((log_im - center) / spread, count, total))
    c, s = np.asarray(_newton(jnp.asarray(x), jnp.asarray(k), jnp.asarray(n)))
    return float(np.exp(center + spread * c / s)), float(spread / s)


# Newton stops once a step (in standardized ln IM) is below this, or after
# this many iterations.
_NEWTON_TOLERANCE = 1e-13
_NEWTON_ITERATIONS = 100
# The relative rounding of a log-likelihood, a sum of float64 terms.
_ROUNDING = 1e-13


def _log_likelihood(p, x, k, n):
    """The binomial log-likelihood of k failures of n at x, with z = s x - c."""
    z = p[1] * x - p[0]
    return jnp.sum(k * log_ndtr(z) + (n - k) * log_ndtr(-z))


@jax.jit
def _newton(x, k, n):
    """(c, s) maximising `_log_likelihood` (concave): Newton from (0, 1),
    halving a step while the log-likelihood falls by more than its rounding."""

    def value(p):
        return _log_likelihood(p, x, k, n)

    def newton_step(carry):
        p, _, i = carry
        g = jax.grad(value)(p)
        step = -jnp.linalg.solve(jax.hessian(value)(p), g)
        now = value(p)

        # A step that falls by more than the value's rounding (a NaN counts
        # as a fall) is halved: near the maximum the value moves by less
        # than its rounding, and Newton's full steps converge.
        floor = now - _ROUNDING * jnp.abs(now)

        def worse(t):
            return ~(value(p + t * step) >= floor) & (t > 1e-10)

        t = jax.lax.while_loop(worse, lambda t: 0.5 * t, 1.0)
        return p + t * step, jnp.max(jnp.abs(t * step)), i + 1

    def going(carry):
        _, size, i = carry
        return (size > _NEWTON_TOLERANCE) & (i < _NEWTON_ITERATIONS)

    start = (jnp.array([0.0, 1.0]), jnp.inf, 0)
    p, _, _ = jax.lax.while_loop(going, newton_step, start)
    return p


# The damage states by kind: the block's, from the least to the most severe
# (uplift < rotation:X < overturning), and the isolator's (displacement:D).
DAMAGE_STATES = ("uplift", "rotation:X", "overturning", "displacement:D")
_LADDER = {"uplift": "block", "rotation": "block", "overturning": "block"}
_LADDER["displacement"] = "isolator"


def _number_text(value: float) -> str:
    """A threshold as written in a state's name: 0.5, 1, 0.123456789, 1e-300
    (Python's shortest repr, without a trailing ".0")."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _damage_state(text) -> tuple[str, float]:
    """(kind, threshold) of one damage state's name; `ValueError` naming
    `damage_states` for anything else."""
    allowed = (
        "`damage_states` must be names of the form 'uplift', 'rotation:X' "
        "(max |theta| / alpha > X), 'overturning' or 'displacement:D' "
        "(max |u| > D m), X and D finite and > 0"
    )
    if not isinstance(text, str):
        raise ValueError(f"{allowed}, got {text!r}")
    if text in ("uplift", "overturning"):
        return text, 0.0 if text == "uplift" else float("inf")
    kind, _, number = text.partition(":")
    if kind not in ("rotation", "displacement"):
        raise ValueError(f"{allowed}, got {text!r}")
    try:
        threshold = float(number)
    except ValueError:
        raise ValueError(f"{allowed}, got {text!r}") from None
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"{allowed}, got {text!r}")
    return kind, threshold


def check_damage_states(states, slenderness, base) -> tuple[tuple, tuple]:
    """The canonical names and the (kind, threshold) of `states`, checked:
    each a name of `DAMAGE_STATES`, the block's states from the least to the
    most severe and the isolator's capacities increasing (each state implies
    the one before it of its kind), a rotation below pi / (2 alpha), a
    displacement only on an isolated base."""
    if states is None:
        return (), ()
    if isinstance(states, str):
        states = (states,)
    try:
        states = tuple(states)
    except TypeError:
        raise ValueError(
            "`damage_states` must be a sequence of names such as 'uplift', "
            f"'rotation:0.5', 'overturning', got {states!r}"
        ) from None
    parsed = [_damage_state(s) for s in states]
    names = tuple(
        kind if kind in ("uplift", "overturning") else f"{kind}:{_number_text(t)}"
        for kind, t in parsed
    )
    alpha = float(np.arctan(1.0 / slenderness))
    last = {}
    for name, (kind, threshold) in zip(names, parsed):
        ladder = _LADDER[kind]
        if ladder in last and threshold <= last[ladder][1]:
            raise ValueError(
                "`damage_states` must nest: each state of the block (uplift, "
                "rotation:X, overturning) more severe than the one before it, "
                "each displacement:D larger, and none twice; got "
                f"{name!r} after {last[ladder][0]!r}"
            )
        last[ladder] = (name, threshold)
        if kind == "rotation" and threshold >= 0.5 * np.pi / alpha:
            raise ValueError(
                f"`damage_states`: {name!r} is beyond the block's reach: "
                "max |theta| / alpha is at most pi / (2 alpha) = "
                f"{0.5 * np.pi / alpha:.4g} (on the ground), which is 'overturning'"
            )
        if kind == "displacement" and isinstance(base, FixedBase):
            raise ValueError(
                f"`damage_states`: {name!r} is a displacement of the isolator, "
                "and a FixedBase does not move"
            )
        reach = None if kind != "displacement" else _displacement_reach(base)
        if reach is not None and threshold > reach:
            raise ValueError(
                f"`damage_states`: {name!r} is beyond the isolator's reach: an "
                f"analysis whose max |u| reaches {reach:g} m (its capacity "
                "without a stop, or its geometric limit) ends CAPACITY_EXCEEDED, "
                "and its max |u| past that is the unbounded model's; give "
                f"D <= {reach:g} m (or a `stop` at the capacity)"
            )
    return names, tuple(parsed)


def _displacement_reach(base: AbstractIsolator) -> float | None:
    """The |u| (m) past which an analysis of `base` ends CAPACITY_EXCEEDED
    (its capacity without a stop, its geometric limit), or None."""
    limits = [base.geometric_limit, base.capacity if base.stop is None else None]
    values = [float(np.max(x)) for x in limits if x is not None]
    return min(values) if values else None


def _exceeded(parsed, outcome, max_rotation, max_base_displacement):
    """Whether each analysis (rows) reached each damage state (columns)."""
    columns = []
    for kind, threshold in parsed:
        if kind == "uplift":
            columns.append(outcome != Outcome.NO_ROCKING)
        elif kind == "overturning":
            columns.append(outcome == Outcome.OVERTURNED)
        elif kind == "rotation":
            columns.append(max_rotation > threshold)
        else:
            columns.append(max_base_displacement > threshold)
    return np.stack(columns, axis=-1) if columns else np.zeros((outcome.size, 0), bool)


class ConfidenceBand(NamedTuple):
    """A bootstrap confidence band of a fragility curve
    (`Fragility.confidence_band`): at each IM of `im` the central `level` of
    the refitted P(state | IM) lies between `lower` and `upper`; `median`
    and `beta` hold the same quantiles of the refitted medians (units of IM)
    and betas (-); `fitted` counts the resamples with a fit."""

    im: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    median: np.ndarray
    beta: np.ndarray
    level: float
    fitted: int


class Fragility(eqx.Module):
    """The results of `fragility`: one row per analysis, and lognormal fits.

    Each row is one analysis of the block under one motion of the ensemble,
    at one scale. P(rocking | IM) and P(overturning | IM) are fitted as
    Phi(ln(IM / median) / beta) by maximum likelihood over the analyses whose
    status is SUCCESS (`fit_lognormal`); `probability` evaluates the fits.

    Attributes:
        im: the intensity measure of each analysis, in the units of
            `measure`.
        rocked: whether each analysis rocked, overturning included (bool).
        overturned: whether each analysis overturned (bool).
        status: the `Status` codes.
        measure: the intensity measure, a name of `intensity_measure`
            (e.g. "pga", m/s^2; "sa:1.0", Sa(1 s) in m/s^2; "pga_ratio",
            the dimensionless PGA / (g tan alpha)).
        median_rocking: the median of the fit of P(rocking), in the units of
            `im`; NaN when every or no analysis rocked, or when rocking does
            not lean to larger IM (see `fit_lognormal`).
        beta_rocking: the fit's standard deviation of ln IM (-); NaN likewise,
            and 0 when no analysis that rocked has a smaller IM than one that
            did not (a step at the median, see `fit_lognormal`), as for one
            motion scaled.
        median_overturning: the median of the fit of P(overturning), in the
            units of `im`; NaN when every or no analysis overturned, or
            when overturning does not lean to larger IM.
        beta_overturning: the fit's standard deviation of ln IM (-); NaN
            likewise, and 0 for separated outcomes as `beta_rocking`.
        slenderness: the block's lambda = h / b (-).
        size: the block's half-diagonal r (m).
        base: a description of the base.
        motion: a description of the motions as given, and of their scales
            or levels.
        seconds: the wall time of the analyses (s).
        scales: the amplitude factors (-); None for motions as given.
        levels: the intensity levels of a multiple-stripe analysis (in the
            units of `im`); None otherwise.
        coordinates: the motions' batch axes and the parameters of the base
            and the motions (before scaling) along them (`Coordinates`).
        motion_index: the motion of the ensemble (before scaling) of each row.
        motion_names: the records' names of a suite; None otherwise.
        max_rotation: max |theta| / alpha of each analysis (-), pi / (2 alpha)
            where the block overturned.
        max_base_displacement: max |u| of each analysis (m); 0 on a fixed base.
        damage_states: the names of the damage states (`fragility`), e.g.
            ("uplift", "rotation:0.5", "overturning"); () when none were asked.
        exceeded: whether each analysis reached each damage state (bool),
            shape (rows, damage states).
        median_damage: the median of each damage state's fit, in the units of
            `im` (NaN and 0 as `median_rocking`), shape (damage states,).
        beta_damage: each damage state's beta (-), shape (damage states,).

    Examples:
        >>> import jaxrock as jr
        >>> pulse = jr.near_fault_pulse("San Fernando PCD/SN")
        >>> frag = jr.fragility(4.0, 1.0, jr.FixedBase(), pulse,
        ...                     scales=[0.2, 0.4, 0.6, 0.8, 1.0, 1.2])
        >>> frag.im.round(2)  # PGA (m/s^2)
        array([0.87, 1.74, 2.61, 3.48, 4.35, 5.22])
        >>> frag.rocked.astype(int), frag.overturned.astype(int)
        (array([0, 0, 1, 1, 1, 1]), array([0, 0, 0, 1, 1, 1]))
        >>> frag = jr.fragility(4.0, 1.0, jr.FixedBase(), pulse,
        ...                     scales=[0.2, 0.4, 0.6, 0.8, 1.0, 1.2],
        ...                     damage_states=["uplift", "rotation:0.5", "overturning"])
        >>> frag.exceeded.astype(int).T
        array([[0, 0, 1, 1, 1, 1],
               [0, 0, 0, 1, 1, 1],
               [0, 0, 0, 1, 1, 1]])
        >>> frag.median_damage.round(2)  # separated outcomes: steps (beta 0)
        array([2.13, 3.01, 3.01])
    """

    im: np.ndarray
    rocked: np.ndarray
    overturned: np.ndarray
    status: np.ndarray
    measure: str
    median_rocking: float
    beta_rocking: float
    median_overturning: float
    beta_overturning: float
    slenderness: float
    size: float
    base: str
    motion: str
    seconds: float
    scales: np.ndarray | None
    coordinates: Coordinates
    levels: np.ndarray | None = None
    # The motion (before scaling) of each row, and the records' names.
    motion_index: np.ndarray | None = None
    motion_names: tuple | None = None
    max_rotation: np.ndarray | None = None
    max_base_displacement: np.ndarray | None = None
    damage_states: tuple = ()
    exceeded: np.ndarray | None = None
    median_damage: np.ndarray | None = None
    beta_damage: np.ndarray | None = None

    def probability(self, im, which: str = "overturning"):
        """The fitted lognormal P(state | IM) of `which`: "rocking",
        "overturning", or one of `damage_states` (e.g. "rotation:0.5").

        With beta = 0 (separated outcomes, see `fit_lognormal`) the curve is
        its limit, a step: 0 below the median, 1 above it and 1/2 at it.
        """
        if which in ("rocking", "overturning"):
            median = getattr(self, f"median_{which}")
            beta = getattr(self, f"beta_{which}")
        else:
            index = self._state_index(which)
            median, beta = self.median_damage[index], self.beta_damage[index]
        im = _intensities(im)
        if beta == 0:
            return np.where(im > median, 1.0, np.where(im < median, 0.0, 0.5))
        return np.asarray(norm.cdf(np.log(im / median) / beta))

    def _reached(self, which: str) -> np.ndarray:
        """Whether each analysis reached `which`."""
        if which == "rocking":
            return self.rocked
        if which == "overturning":
            return self.overturned
        return self.exceeded[:, self._state_index(which)]

    def _counted(self, which: str) -> np.ndarray:
        """Whether each analysis counts in the fit of `which`: its status is
        SUCCESS, or for a displacement of the isolator also
        CAPACITY_EXCEEDED (`_fitted`)."""
        ok = self.status == Status.SUCCESS
        if which in ("rocking", "overturning"):
            return ok
        name = self.damage_states[self._state_index(which)]
        if name.startswith("displacement"):
            return ok | (self.status == Status.CAPACITY_EXCEEDED)
        return ok

    def confidence_band(
        self,
        which: str = "overturning",
        im=None,
        *,
        samples: int = 500,
        level: float = 0.9,
        seed: int = 0,
    ) -> "ConfidenceBand":
        """A confidence band of the fitted P(`which` | IM) by bootstrap over
        the motions: `samples` times, the ensemble's motions (the records of
        a suite, before scaling) drawn with replacement, their analyses
        refitted (each motion's analyses weighted by the times it was drawn);
        the band holds the central `level` of the refitted curves at each IM
        of `im` (default: 200 points over the analyses' range), and the same
        quantiles of the refitted medians and betas. Resamples without a fit
        (every analysis or none reaching `which`) are left out
        (`ConfidenceBand.fitted` counts the others). Reproducible for a `seed`.
        """
        if not (0 < level < 1) or not is_count(samples) or samples < 2:
            raise ValueError(
                f"`level` must be in (0, 1) and `samples` an integer >= 2, got "
                f"{level!r} and {samples!r}"
            )
        reached = self._reached(which)
        ok = self._counted(which)
        members = self.motion_index
        count = int(members.max()) + 1
        if count < 2:  # every resample would draw it: a band of no width
            raise ValueError(
                "a bootstrap over the motions needs at least 2 motions (a suite "
                "of records), this fragility has 1"
            )
        if im is None:
            im = np.geomspace(self.im.min(), self.im.max(), 200)
        im = _intensities(im)
        log_im = np.log(self.im)
        rng = np.random.default_rng(seed)
        fits = []
        for _ in range(samples):
            drawn = np.bincount(rng.integers(0, count, count), minlength=count)
            weight = (drawn[members] * ok).astype(float)
            fits.append(_fit_counts(log_im, weight * reached, weight))
        fits = np.array([f for f in fits if np.isfinite(f[0])]).reshape(-1, 2)
        if fits.shape[0] < 2:
            raise ValueError(f"too few resamples have a fit of {which!r}")
        log_ratio = np.log(im[None, :] / fits[:, :1])
        beta = fits[:, 1:]
        step = np.where(log_ratio > 0, 1.0, np.where(log_ratio < 0, 0.0, 0.5))
        curves = np.where(
            beta > 0, norm.cdf(log_ratio / np.where(beta > 0, beta, 1.0)), step
        )
        q = [0.5 - level / 2, 0.5 + level / 2]
        lower, upper = np.quantile(curves, q, axis=0)
        return ConfidenceBand(
            im=im,
            lower=lower,
            upper=upper,
            median=np.quantile(fits[:, 0], q),
            beta=np.quantile(fits[:, 1], q),
            level=float(level),
            fitted=int(fits.shape[0]),
        )

    def stripes(self, which: str = "overturning"):
        """A multiple-stripe analysis's counts per level: (levels, k, n), the
        analyses of each level that reached `which` ("rocking",
        "overturning" or a damage state) and those that count (status
        SUCCESS): the binomial data of the fit."""
        if self.levels is None:
            raise ValueError("`stripes` needs a multiple-stripe analysis (`levels`)")
        reached = self._reached(which)
        ok = self._counted(which).reshape(self.levels.size, -1)
        k = np.sum(reached.reshape(self.levels.size, -1) & ok, axis=1)
        return self.levels, k, np.sum(ok, axis=1)

    def _state_index(self, which) -> int:
        """The column of the damage state named `which` (its name as
        `fragility` writes it or as given: "rotation:0.50" is "rotation:0.5")."""
        try:
            kind, threshold = _damage_state(which)
        except ValueError:
            kind = None
        for i, name in enumerate(self.damage_states):
            if kind is not None and _damage_state(name) == (kind, threshold):
                return i
        raise ValueError(
            "`which` must be 'rocking', 'overturning' or one of the damage states "
            f"{list(self.damage_states)}, got {which!r}"
        )

    def to_xarray(self):
        """The analyses as an `xarray.Dataset` over the scales and the motions.

        Dimensions: "scale" (the amplitude factors, -) when `scales` were
        given, then the motions' batch axes ("record" for a suite of records,
        "motion" for a batch of pulses). Coordinates: the scales, the
        parameters of the base and of the motions before scaling (e.g. the
        records' names as `record`, a batch of pulses' `amplitude` in m/s),
        with their units in `attrs`, and the block (0-d `slenderness`, -, and
        `size`, m). Data variables: `im` (in the units of `measure`),
        `rocked`, `overturned` and `status` per analysis, and the fits
        (`median_rocking` and `median_overturning` in the units of `im`,
        `beta_rocking` and `beta_overturning`, -), `max_rotation` (-) and
        `max_base_displacement` (m) per analysis. With `damage_states`, a
        dimension "damage_state" labelled by their names, `exceeded` over the
        analyses' dimensions and it, and the fits `median_damage` (in the
        units of `im`) and `beta_damage` (-) along it. Attributes: `measure`,
        `base`, `motion` and `seconds` (s).

        Needs xarray (`pip install "jaxrock[xarray]"`).

        Examples:
            >>> import jaxrock as jr
            >>> pulse = jr.near_fault_pulse("San Fernando PCD/SN")
            >>> frag = jr.fragility(4.0, 1.0, jr.FixedBase(), pulse,
            ...                     scales=[0.2, 0.4, 0.6, 0.8, 1.0, 1.2])
            >>> ds = frag.to_xarray()
            >>> ds.im.dims, bool(ds.overturned.sel(scale=1.0))
            (('scale',), True)
            >>> frag = jr.fragility(4.0, 1.0, jr.FixedBase(), pulse,
            ...                     scales=[0.2, 0.4, 0.6, 0.8, 1.0, 1.2],
            ...                     damage_states=["rotation:0.5", "overturning"])
            >>> ds = frag.to_xarray()
            >>> ds.exceeded.dims, ds.damage_state.values.tolist()
            (('scale', 'damage_state'), ['rotation:0.5', 'overturning'])
        """
        dims, coords = self.coordinates.dims, dict(self.coordinates.coords)
        if self.scales is not None:
            dims = ("scale",) + dims
            coords["scale"] = (("scale",), self.scales, {"units": "1"})
        if self.levels is not None:
            dims = ("level",) + dims
            coords["level"] = (("level",), self.levels, measure_attrs(self.measure))
        for k in ("slenderness", "size"):
            coords[k] = ((), getattr(self, k), ATTRS[k])
        shape = self.coordinates.sizes()
        leading = self.scales is not None or self.levels is not None
        shape = (-1,) + shape if leading else shape
        im = measure_attrs(self.measure)
        fit = {}
        for which in ("rocking", "overturning"):
            fit[f"median_{which}"] = ((), getattr(self, f"median_{which}"), im)
            fit[f"beta_{which}"] = ((), getattr(self, f"beta_{which}"), {"units": "1"})
        rows = {
            "im": (dims, self.im.reshape(shape), im),
            "rocked": (dims, self.rocked.reshape(shape), {"long_name": "rocked"}),
            "overturned": (
                dims,
                self.overturned.reshape(shape),
                {"long_name": "overturned"},
            ),
            "status": (dims, self.status.reshape(shape)),
        }
        if self.max_rotation is not None:
            rows["max_rotation"] = (dims, self.max_rotation.reshape(shape))
            rows["max_base_displacement"] = (
                dims,
                self.max_base_displacement.reshape(shape),
            )
        if self.damage_states:
            states = len(self.damage_states)
            coords["damage_state"] = (("damage_state",), list(self.damage_states), {})
            rows["exceeded"] = (
                dims + ("damage_state",),
                self.exceeded.reshape(shape + (states,)),
                {"long_name": "damage state reached"},
            )
            fit["median_damage"] = (("damage_state",), self.median_damage, im)
            fit["beta_damage"] = (("damage_state",), self.beta_damage, {"units": "1"})
        attrs = dict(
            measure=self.measure,
            base=self.base,
            motion=self.motion,
            seconds=self.seconds,
        )
        return dataset(rows | fit, coords, attrs)


def _moving_measure(motions, measure, slenderness, size):
    """The intensity measure of each motion; `ValueError` if one does not move
    the ground (a measure of 0)."""
    im = np.reshape(
        intensity_measure(motions, measure, slenderness=slenderness, size=size), -1
    )
    if not np.all(im > 0):
        raise ValueError(
            "every motion of `motions` must move the ground (an intensity measure "
            f"> 0): {int(np.sum(~(im > 0)))} of them have zero amplitude"
        )
    return im


def fragility(
    slenderness: float,
    size: float,
    base: AbstractIsolator,
    motions: AbstractGroundMotion,
    *,
    scales=None,
    levels=None,
    measure: str = "pga",
    damage_states=None,
    **map_options,
) -> Fragility:
    """Rocking and overturning of one block over an ensemble of motions.

    The standard incremental analysis of rocking objects: every motion of a
    suite of records (`Record.stack`) at every factor of `scales`, or any
    batched motion (a batched `MPPulse`, a suite) as it is. Or a
    multiple-stripe analysis: every record scaled so that its own `measure`
    equals each of `levels`, whose analyses at one level enter the
    likelihood as one binomial term (Baker 2015; `Fragility.stripes`). The
    analyses run as one behavior map with motion axes. The intensity measure
    of each analysis is computed from its own scaled motion by
    `intensity_measure` (the block's measures with this block). P(rocking)
    and P(overturning) are fitted as lognormal curves by maximum likelihood
    over the analyses whose status is SUCCESS, and so is each of
    `damage_states`, a ladder of states of increasing severity defined on
    the results: "uplift" (the block rocked), "rotation:X" (max |theta| /
    alpha > X, the block's rotation as a fraction of its critical angle
    alpha), "overturning", and the isolator's "displacement:D" (max |u| > D
    m, a capacity). The block's states are given from the least to the most
    severe, an isolator's capacities in increasing order: each state implies
    the one before it of its kind. Analyses past an isolator's `capacity`
    count in the displacement states only, those whose block slides (a
    `friction`) in none.

    Args:
        slenderness: the block's lambda = h / b.
        size: the block's half-diagonal r (m).
        base: the base (`FixedBase`, `LinearIsolator`, `FrictionPendulum`).
        motions: a suite of records, one record (with `scales`), or a batched
            pulse.
        scales: amplitude factors (> 0) applied to every motion; None: the
            motions as given.
        levels: instead of `scales`, intensity levels (> 0, in the units of
            `measure`) to scale every record of `motions` (a `Record` or a
            suite) to: a measure that grows with a record's amplitude
            (not "d5_95", "tp" or "frequency_ratio"; "arias" grows as its
            square).
        measure: a name of `intensity_measure`; default "pga".
        damage_states: names of damage states (above), e.g.
            ["uplift", "rotation:0.5", "overturning", "displacement:0.2"];
            None: none.
        **map_options: passed to `behavior_map` (rtol, duration, store,
            executor, ...).

    Returns:
        A `Fragility`: one row per analysis (scales first, then motions),
        with `motion_index` the motion each row scales and the fits.

    Raises:
        ValueError: an unknown measure, a batch of bases, `scales` not all
            > 0, a single unscaled motion, a single motion with `scales` and
            a measure that does not grow with its amplitude, a motion that
            does not move the ground, or `damage_states` that are malformed,
            do not nest, ask for a rotation of pi / (2 alpha) or more, or for
            the displacement of a fixed base.

    Examples:
        >>> import jaxrock as jr
        >>> pulse = jr.near_fault_pulse("San Fernando PCD/SN")
        >>> frag = jr.fragility(4.0, 1.0, jr.FixedBase(), pulse,
        ...                     scales=[0.2, 0.5, 1.0, 1.5])  # doctest: +SKIP
    """
    states, parsed = _checked(measure, base, motions, slenderness, size, damage_states)
    one_block_options(map_options, "a fragility")
    sources, names = _sources(motions)
    labels = coordinates(base, motions)
    described = _described(motions, scales, levels, measure)
    motions, scales, levels = _scaled(
        motions, scales, levels, measure, slenderness, size
    )
    im = _measured(motions, levels, measure, slenderness, size)
    bm = behavior_map([slenderness], [size], base, motions, **map_options)
    return Fragility(
        **_fitted(bm, im, parsed),
        measure=measure,
        slenderness=float(slenderness),
        size=float(size),
        base=bm.base,
        motion=described,
        seconds=bm.seconds,
        scales=scales,
        levels=levels,
        coordinates=labels,
        motion_index=np.tile(sources, bm.outcome.size // sources.size),
        motion_names=names,
        damage_states=states,
    )


def _sources(motions) -> tuple[np.ndarray, tuple | None]:
    """(the motion of the ensemble each of `motions` is, flattened; the
    records' names, or None): a suite scaled beforehand (`Record.scaled`,
    its factors' axes first) is its records at each factor, whose analyses
    a bootstrap draws together; any other motion is its own."""
    shape, names = motions.batch_shape, motions.names()
    if not isinstance(motions, Record):
        return np.arange(int(np.prod(shape))), names
    records = np.shape(motions.unscaled)[:-1]
    index = np.arange(int(np.prod(records))).reshape(records)
    sources = np.broadcast_to(index, shape).ravel()
    if names is not None:  # one per record, from its first motion
        first = np.unique(sources, return_index=True)[1]
        names = tuple(names[i] for i in first)
    return sources, names


def _described(motions, scales, levels, measure) -> str:
    """The motions as given, and their scales or levels (`Fragility.motion`)."""
    text = motions.describe()
    if scales is not None:
        text += f", at {np.size(scales)} scales"
    if levels is not None:
        text += f", scaled to {np.size(levels)} levels of {measure}"
    return text


def _measured(motions, levels, measure, slenderness, size) -> np.ndarray:
    """The measure of each analysis. Of a multiple-stripe analysis, its
    stripe's level: its records' measures equal it but for rounding (1 ulp),
    which must not order the analyses of one level (ties of a stripe, its
    binomial term)."""
    if levels is None:
        return _moving_measure(motions, measure, slenderness, size)
    shape = motions.batch_shape
    stripes = levels.reshape((-1,) + (1,) * (len(shape) - 1))
    return np.broadcast_to(stripes, shape).reshape(-1)


def _checked(measure, base, motions, slenderness, size, damage_states):
    """`fragility`'s arguments checked before any analysis (`ValueError`
    naming the one at fault); returns `check_damage_states`'s (states,
    parsed)."""
    parse_measure(measure)
    check_base_and_motion(base, motions)
    unbatched("base", base, "fragility")
    for name, x in (("slenderness", slenderness), ("size", size)):
        positive(name, one_real_number(name, x, "finite and > 0"))
    return check_damage_states(damage_states, slenderness, base)


# How each measure grows with a record's amplitude factor f: as f^power (None:
# not at all).
_POWERS = {"arias": 2.0, "d5_95": None, "tp": None, "frequency_ratio": None}


def _scaled(motions, scales, levels, measure, slenderness, size):
    """(the motions to analyse, scales, levels): every record scaled to each
    of `levels` of `measure` (`_stripes`), or by each of `scales`
    (`_ensemble`); the one not given is None."""
    if levels is not None and scales is not None:
        raise ValueError("give `scales` or `levels`, not both")
    if levels is not None:
        motions, levels = _stripes(motions, levels, measure, slenderness, size)
        return motions, None, levels
    if scales is not None and motions.batch_shape == ():
        name, _ = parse_measure(measure)
        if _POWERS.get(name, 1.0) is None:
            raise ValueError(
                f"`measure` {measure!r} does not grow with a motion's amplitude: "
                "one motion at every factor of `scales` has one value of it, "
                "which no fit can use (use another measure, or a suite of motions)"
            )
    motions, scales = _ensemble(motions, scales)
    return motions, scales, None


def _stripes(motions, levels, measure, slenderness, size):
    """The records of `motions` scaled to each of `levels` of `measure` (the
    factors' axis first), and the levels."""
    levels = grid_axis("levels", levels)
    positive("levels", levels)
    if not isinstance(motions, Record):
        raise ValueError(
            "a multiple-stripe analysis (`levels`) scales records: `motions` must "
            f"be a Record or a suite of records, got {type(motions).__name__}"
        )
    name, _ = parse_measure(measure)
    power = _POWERS.get(name, 1.0)
    if power is None:
        raise ValueError(
            f"`measure` {measure!r} does not grow with a record's amplitude: no "
            "scaling reaches a level of it (use another measure with `levels`)"
        )
    own = _moving_measure(motions, measure, slenderness, size).reshape(
        motions.batch_shape
    )
    factors = (levels.reshape((-1,) + (1,) * own.ndim) / own) ** (1.0 / power)
    labels = {k: v * levels.size for k, v in motions.labels(flat=True).items()}
    return motions._rebuilt(jnp.asarray(factors), **labels), levels


def _ensemble(motions, scales):
    """The motions at every factor of `scales` (and the factors), or, with
    `scales` None, the motions as given, which must then be an ensemble."""
    if scales is not None:
        scales = scale_factors(grid_axis("scales", scales), "scales")
        return motions.scaled(scales), scales
    if motions.batch_shape == ():
        raise ValueError(
            "`motions` must be an ensemble (a suite of records or a batched pulse), "
            "or give `scales`"
        )
    return motions, None


def _fitted(bm, im, parsed) -> dict:
    """A fragility's per-analysis results (one row per cell of the map `bm`,
    its intensity measures `im`) and the lognormal fits of P(rocking),
    P(overturning) and of each parsed damage state over the analyses whose
    status is SUCCESS (the isolator's displacement states also over those
    whose base passed its capacity: their max |u| is that of the isolator
    without its stop, which passes any displacement up to the capacity)."""
    outcome = bm.outcome.reshape(-1)
    im = np.broadcast_to(im, outcome.shape)
    status = bm.status.reshape(-1)
    ok = status == Status.SUCCESS
    ok_u = ok | (status == Status.CAPACITY_EXCEEDED)
    rocked = outcome != Outcome.NO_ROCKING
    overturned = outcome == Outcome.OVERTURNED
    med_r, beta_r = fit_lognormal(im[ok], rocked[ok])
    med_o, beta_o = fit_lognormal(im[ok], overturned[ok])
    max_rotation = bm.max_rotation.reshape(-1)
    max_u = bm.max_base_displacement.reshape(-1)
    exceeded = _exceeded(parsed, outcome, max_rotation, max_u)
    fits = []
    for (kind, _), reached in zip(parsed, exceeded.T):
        counted = ok_u if kind == "displacement" else ok
        fits.append(fit_lognormal(im[counted], reached[counted]))
    fits = np.array(fits).reshape(-1, 2)
    return dict(
        im=np.asarray(im),
        rocked=rocked,
        overturned=overturned,
        status=bm.status.reshape(-1),
        median_rocking=med_r,
        beta_rocking=beta_r,
        median_overturning=med_o,
        beta_overturning=beta_o,
        max_rotation=max_rotation,
        max_base_displacement=max_u,
        exceeded=exceeded,
        median_damage=fits[:, 0],
        beta_damage=fits[:, 1],
    )


def _intensities(im) -> np.ndarray:
    """`im` (intensities at which to read a curve) as floats, each finite
    and > 0 (`ValueError` naming `im` otherwise; a lognormal curve has no
    value at IM <= 0)."""
    im = np.asarray(im, dtype=float)
    if im.size:
        positive("im", im)
    return im
