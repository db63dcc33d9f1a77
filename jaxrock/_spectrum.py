"""Overturning spectra: where a pulse overturns a block, in dimensionless form."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._block import Block
from ._ground import SinePulse
from ._isolators import AbstractIsolator
from ._maps import behavior_map
from ._misc import positive
from ._simulate import Outcome, Status


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
    fr = np.atleast_1d(np.asarray(frequency_ratio, dtype=float))
    ar = np.atleast_1d(np.asarray(amplitude_ratio, dtype=float))
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
        status=status,
        minimum=minimum,
        base=bm.base,
    )
