"""Overturning spectra: where a pulse overturns a block, in dimensionless form."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._block import Block
from ._ground import SinePulse
from ._isolators import AbstractIsolator
from ._maps import behavior_map
from ._misc import grid_axis, positive
from ._results import Outcome, Status


class OverturningSpectrum(eqx.Module):
    """Outcomes of one block over (omega_p / p, a_p / (g tan alpha)).

    `outcome` and `status` have shape (n_frequency, n_amplitude). `minimum` is
    the lowest amplitude ratio of the sweep that overturns the block at each
    frequency ratio (NaN if none does): the lower edge of the overturning
    region, above which safe islands may still exist (`outcome`).
    """

    frequency_ratio: np.ndarray
    amplitude_ratio: np.ndarray
    outcome: np.ndarray
    impacts: np.ndarray  # impacts before overturning: 0 is Makris & Roussos's mode 2
    status: np.ndarray
    minimum: np.ndarray
    base: str


def overturning_spectrum(
    block: Block,
    base: AbstractIsolator,
    frequency_ratio,
    amplitude_ratio,
    **map_options,
) -> OverturningSpectrum:
    """Sweep one-sine pulses (`SinePulse`) over omega_p / p and a_p / (g tan alpha).

    omega_p = 2 pi f_p is the pulse's circular frequency, p = sqrt(3 g / (4 r))
    the block's frequency parameter and g tan(alpha) its uplift acceleration.
    Every (frequency, amplitude) pair is one exact analysis; they run as one
    behavior map with a motion axis (`map_options` go to `behavior_map`).
    """
    fr = grid_axis("frequency_ratio", frequency_ratio)
    ar = grid_axis("amplitude_ratio", amplitude_ratio)
    positive("frequency_ratio", fr)
    positive("amplitude_ratio", ar)
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
    minimum = np.where(over.any(axis=1), ar[np.argmax(over, axis=1)], np.nan)
    return OverturningSpectrum(
        frequency_ratio=fr,
        amplitude_ratio=ar,
        outcome=outcome,
        impacts=bm.impacts.reshape(F.shape),
        status=status,
        minimum=minimum,
        base=bm.base,
    )


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
    phi = 1.0 - k * np.sin(w * (tau + tu)) + a * np.cosh(tau) + b * np.sinh(tau)
    return (a + b) * np.exp(2 * np.pi / w - tu) - k * w, phi.min(axis=0)


def linearized_overturning_amplitude(frequency_ratio) -> np.ndarray:
    """Minimum a_p / (g alpha) that overturns a slender fixed-base block without
    impact under a one-sine pulse (Makris & Roussos 2000, mode 2), linearized.

    The closed-form solution of the linearized equation of rocking (valid as
    alpha -> 0); the amplitude is bracketed on a geometric grid and refined by
    bisection (escape at the pulse's end with no impact before). `frequency_ratio` is
    omega_p / p (> 0). The exact (nonlinear) lower edge of the no-impact
    overturning region approaches it as alpha -> 0 (tested: within 0.5% at
    slenderness 20).
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
