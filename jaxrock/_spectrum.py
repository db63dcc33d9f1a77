"""Overturning spectra: where a pulse overturns a block, in dimensionless form."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._block import Block
from ._ground import SinePulse
from ._isolators import AbstractIsolator
from ._labeled import ATTRS, Coordinates, coordinates, dataset
from ._maps import behavior_map
from ._misc import grid_axis, one_block_options, positive, unbatched
from ._results import Outcome, Status


class OverturningSpectrum(eqx.Module):
    """The outcomes of one block under a grid of one-sine pulses.

    The result of `overturning_spectrum`. Its axes are dimensionless: the
    frequency ratio omega_p / p, with omega_p = 2 pi f_p (rad/s) the pulse's
    circular frequency and p = sqrt(3 g / (4 r)) (rad/s) the block's
    frequency parameter, and the amplitude ratio a_p / (g tan alpha), with
    a_p (m/s^2) the pulse's peak acceleration and g tan(alpha) (m/s^2) the
    block's uplift acceleration.

    Attributes:
        frequency_ratio: omega_p / p (-), 1-D, n_frequency values.
        amplitude_ratio: a_p / (g tan alpha) (-), 1-D, n_amplitude values.
        outcome: the `Outcome` codes, shape (n_frequency, n_amplitude).
        impacts: the impacts of each analysis, same shape; 0 where the block
            overturns is overturning without impact (Makris & Roussos's
            mode 2).
        status: the `Status` codes, same shape.
        minimum: at each frequency ratio, the lowest amplitude ratio of the
            grid that overturns the block in an analysis whose status is
            SUCCESS (NaN if none does): the lower edge of the overturning
            region, above which safe islands may still exist (`outcome`).
        base: a description of the base.
        slenderness: the block's lambda = h / b (-).
        size: the block's half-diagonal r (m).
        seconds: the wall time of the analyses (s).
        coordinates: the base's parameters (`Coordinates`, no axes).

    Examples:
        >>> import jaxrock as jr
        >>> s = jr.overturning_spectrum(jr.Block(10.0, 1.0), jr.FixedBase(),
        ...                             [2.0, 4.0], [1.5, 3.0, 6.0])
        >>> s.impacts
        array([[  1,   0,   0],
               [431,   1,   0]])
    """

    frequency_ratio: np.ndarray
    amplitude_ratio: np.ndarray
    outcome: np.ndarray
    impacts: np.ndarray  # impacts before overturning: 0 is Makris & Roussos's mode 2
    status: np.ndarray
    minimum: np.ndarray
    base: str
    slenderness: float
    size: float
    seconds: float
    coordinates: Coordinates

    def to_xarray(self):
        """The spectrum as an `xarray.Dataset` over the two ratios.

        Dimensions: "frequency_ratio" (omega_p / p, -) and "amplitude_ratio"
        (a_p / (g tan alpha), -). Coordinates: the two ratios, the block (0-d
        `slenderness`, -, and `size`, m) and the base's parameters (0-d, units
        in `attrs`). Data variables: `outcome`, `impacts` and `status` over
        both ratios (meanings and codes in `attrs`), and `minimum` over the
        frequency ratios. Attributes: `base`, `motion` and `seconds` (s).

        Needs xarray (`pip install "jaxrock[xarray]"`).

        Examples:
            >>> import jaxrock as jr
            >>> s = jr.overturning_spectrum(jr.Block(10.0, 1.0), jr.FixedBase(),
            ...                             [2.0, 4.0], [1.5, 3.0, 6.0])
            >>> ds = s.to_xarray()
            >>> ds.impacts.sel(frequency_ratio=4.0).values
            array([431,   1,   0])
        """
        dims = ("frequency_ratio", "amplitude_ratio")
        coords = {
            "frequency_ratio": (dims[:1], self.frequency_ratio, _RATIOS[0]),
            "amplitude_ratio": (dims[1:], self.amplitude_ratio, _RATIOS[1]),
        }
        for k in ("slenderness", "size"):
            coords[k] = ((), getattr(self, k), ATTRS[k])
        minimum = {"long_name": "lowest overturning amplitude ratio", "units": "1"}
        data = {k: (dims, getattr(self, k)) for k in ("outcome", "impacts", "status")}
        data["minimum"] = (dims[:1], self.minimum, minimum)
        attrs = dict(base=self.base, motion=_MOTION, seconds=self.seconds)
        return dataset(data, coords | self.coordinates.coords, attrs)


_RATIOS = (
    {"long_name": "omega_p / p", "units": "1"},
    {"long_name": "a_p / (g tan alpha)", "units": "1"},
)
_MOTION = "one-sine pulses, a_p sin(omega_p t) for 0 <= t <= 2 pi / omega_p"


def overturning_spectrum(
    block: Block,
    base: AbstractIsolator,
    frequency_ratio,
    amplitude_ratio,
    **map_options,
) -> OverturningSpectrum:
    """Sweep one-sine pulses (`SinePulse`) over omega_p / p and a_p / (g tan alpha).

    Each pair of ratios is the pulse x_g'' = a_p sin(omega_p t) (m/s^2) of
    circular frequency omega_p = 2 pi f_p (rad/s), a multiple of the block's
    frequency parameter p = sqrt(3 g / (4 r)) (rad/s), and of amplitude a_p, a
    multiple of the block's uplift acceleration g tan(alpha) (m/s^2). Every
    pair is one exact analysis; they run as one behavior map with a motion
    axis.

    Args:
        block: the block (one slenderness and one size), with its own
            coefficient of restitution and `friction`, if it has them.
        base: the base (`FixedBase()`, `LinearIsolator(...)`, ...).
        frequency_ratio: omega_p / p (-), a 1-D array of values > 0.
        amplitude_ratio: a_p / (g tan alpha) (-), a 1-D array of values > 0.
        **map_options: passed to `behavior_map` (`duration` in s, `rtol`,
            `executor`, ...; a `restitution_factor`, `restitution` or
            `friction` that the block sets too is refused).

    Returns:
        An `OverturningSpectrum` of shape (n_frequency, n_amplitude).

    Raises:
        ValueError: a ratio that is not > 0, an axis that is not a non-empty
            1-D array of real numbers, a batch of bases, or an invalid base or
            map option.

    Examples:
        >>> import jaxrock as jr
        >>> s = jr.overturning_spectrum(jr.Block(10.0, 1.0), jr.FixedBase(),
        ...                             [2.0, 4.0], [1.5, 3.0, 6.0])
        >>> s.outcome
        array([[2, 2, 2],
               [1, 2, 2]])
        >>> s.minimum
        array([1.5, 3. ])
    """
    fr = grid_axis("frequency_ratio", frequency_ratio)
    ar = grid_axis("amplitude_ratio", amplitude_ratio)
    positive("frequency_ratio", fr)
    positive("amplitude_ratio", ar)
    unbatched("base", base, "spectrum")
    if not isinstance(block, Block):
        raise ValueError(f"`block` must be a Block, got {type(block).__name__}")
    unbatched("block", block, "spectrum")
    one_block_options(map_options, "an overturning spectrum")
    map_options = _block_options(block, map_options)
    p = float(block.p)
    uplift = float(block.uplift_acceleration)
    F, A = np.meshgrid(fr, ar, indexing="ij")
    motions = SinePulse(
        jnp.asarray(A.ravel() * uplift), jnp.asarray(F.ravel() * p / (2 * np.pi))
    )
    bm = behavior_map(
        [float(block.slenderness)], [float(block.size)], base, motions, **map_options
    )
    outcome = bm.outcome.reshape(F.shape)
    status = bm.status.reshape(F.shape)
    over = (outcome == Outcome.OVERTURNED) & (status == Status.SUCCESS)
    # The lowest overturning amplitude, whatever the order of the axis.
    lowest = np.where(over, ar[None, :], np.inf).min(axis=1)
    minimum = np.where(np.isfinite(lowest), lowest, np.nan)
    return OverturningSpectrum(
        frequency_ratio=fr,
        amplitude_ratio=ar,
        outcome=outcome,
        impacts=bm.impacts.reshape(F.shape),
        status=status,
        minimum=minimum,
        base=bm.base,
        slenderness=float(block.slenderness),
        size=float(block.size),
        seconds=bm.seconds,
        coordinates=coordinates(base),
    )


def _block_options(block: Block, map_options: dict) -> dict:
    """`map_options` with the block's own coefficient of restitution and
    friction, which `behavior_map` takes as keywords (its grid gives only the
    slenderness and size); `ValueError` where the block and `map_options`
    both set one (a `restitution_factor` of 1, the default, sets none)."""
    own = {}
    if block.restitution is not None:
        own["restitution"] = float(block.restitution)
    elif float(block.restitution_factor) != 1.0:
        own["restitution_factor"] = float(block.restitution_factor)
    if block.friction is not None:
        own["friction"] = float(block.friction)
    given = {"restitution", "restitution_factor"} & set(map_options)
    clash = [k for k in own if k in map_options or (k != "friction" and given)]
    if clash:
        raise ValueError(
            f"`{clash[0]}` is given twice: set it on the `block` or as a keyword, "
            "not both"
        )
    return map_options | own


def _mode2_margin(psi, w, samples=1001):
    """Linearized one-sine response (time in units of 1 / p) at amplitudes psi.

    phi = theta / alpha obeys phi'' - phi = psi sin(w t) - 1 from the uplift
    (sin(w t_u) = 1 / psi) with phi = phi' = 0. Returns the escape margin at the
    pulse's end, phi' + phi - 1 (> 0: free rocking carries the block over), and
    the smallest phi during the pulse (< 0: an impact came first).
    """
    psi = np.maximum(psi, 1.0 + 1e-12)
    tu = np.arcsin(1.0 / psi) / w
    k = psi / (1.0 + w**2)
    a = k / psi - 1.0
    b = k * w * np.cos(w * tu)
    tau = np.linspace(0.0, 1.0, samples)[1:, None] * (2 * np.pi / w - tu)
    # a cosh + b sinh as exponentials: on a long pulse (small w) e^tau
    # overflows to the sign of a + b, where cosh - sinh would give inf - inf.
    with np.errstate(over="ignore", invalid="ignore"):
        grow = np.where(a + b == 0.0, 0.0, 0.5 * (a + b) * np.exp(tau))
        phi = 1.0 - k * np.sin(w * (tau + tu)) + grow + 0.5 * (a - b) * np.exp(-tau)
        margin = np.where(
            a + b == 0.0, -k * w, (a + b) * np.exp(2 * np.pi / w - tu) - k * w
        )
    return margin, phi.min(axis=0)


def linearized_overturning_amplitude(frequency_ratio) -> np.ndarray:
    """The linearized one-sine amplitude a_p / (g alpha) that overturns without impact.

    For a slender block on a fixed base (alpha -> 0), the linearized equation
    of rocking, phi'' - phi = psi sin(w tau) - 1 in phi = theta / alpha, the
    time tau = p t, w = omega_p / p and psi = a_p / (g alpha), has a closed-form
    solution. The least psi whose pulse carries the block past the separatrix
    at the pulse's end with no impact before is bracketed on a geometric grid
    (up to 1e4) and refined by bisection: the lower edge of overturning without
    impact (Makris & Roussos 2000, mode 2). The exact (nonlinear) lower edge
    approaches it as alpha -> 0 (within 0.5% at slenderness 20); a_p is the
    pulse's peak acceleration (m/s^2) and omega_p = 2 pi f_p (rad/s).

    Args:
        frequency_ratio: w = omega_p / p (-), one value or a 1-D array of
            values > 0.

    Returns:
        A NumPy array of psi = a_p / (g alpha) (-), one per frequency ratio;
        NaN where no amplitude up to 1e4 overturns without impact.

    Raises:
        ValueError: a ratio that is not > 0, or an axis that is not a
            non-empty 1-D array of real numbers.

    Examples:
        >>> import jaxrock as jr
        >>> jr.linearized_overturning_amplitude([2.0, 4.0, 8.0]).round(3)
        array([ 2.35 ,  5.239, 14.871])
    """
    ratios = grid_axis("frequency_ratio", frequency_ratio)
    positive("frequency_ratio", ratios)
    grid = np.geomspace(1.0 + 1e-9, 1e4, 200)
    out = np.full(ratios.shape, np.nan)
    for i, w in enumerate(ratios):

        def overturns(psi):
            margin, low = _mode2_margin(psi, w)
            return (margin > 0) & (low > 0)

        ok = overturns(grid)
        if not ok.any():
            continue
        j = int(np.argmax(ok))
        lo, hi = grid[max(j - 1, 0)], grid[j]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if overturns(mid) else (mid, hi)
        out[i] = hi
    return out
