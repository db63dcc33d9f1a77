"""Overturning spectra under one-sine pulses, checked against the SciPy reference."""

import math
import warnings

import numpy as np
import pytest
import reference as ref

import jaxrock as jr

BLOCK = jr.Block(4.0, 1.0)
FREQ = np.array([0.5, 2.0, 4.0, 6.0])
AMP = np.linspace(1.0, 6.0, 11)


@pytest.fixture(scope="module")
def fixed_spectrum():
    return jr.overturning_spectrum(BLOCK, jr.FixedBase(), FREQ, AMP, progress=False)


def _reference_outcome(freq_ratio, amp_ratio):
    p, g_tan = float(BLOCK.p), float(BLOCK.uplift_acceleration)
    a_p, f_p = amp_ratio * g_tan, freq_ratio * p / (2 * math.pi)

    def acc(t):
        return a_p * math.sin(2 * math.pi * f_p * t) if 0 <= t <= 1 / f_p else 0.0

    # The map's window: the longest pulse of the sweep plus 5 s.
    t_end = 2 * math.pi / (FREQ.min() * p) + 5.0
    return ref.simulate(4.0, 1.0, ("fixed",), acc, t_end, 1 / (32 * f_p))["outcome"]


def test_spectrum_cells_match_reference(fixed_spectrum):
    s = fixed_spectrum
    assert s.outcome.shape == (4, 11) and np.all(s.status == jr.Status.SUCCESS)
    for i in range(len(FREQ)):
        # The lower edge and its neighbour below, where a wrong answer would show.
        j = int(np.argmax(s.outcome[i] == jr.Outcome.OVERTURNED))
        for k in {max(j - 1, 0), j}:
            assert s.outcome[i, k] == _reference_outcome(FREQ[i], AMP[k]), (i, k)


def test_spectrum_shape(fixed_spectrum):
    m = fixed_spectrum.minimum
    # A slow pulse overturns the block little above the uplift acceleration; a
    # fast one needs far more (the minimum rises with omega_p / p).
    assert 1.0 < m[0] < 1.6
    assert np.all(np.diff(m[1:]) > 0) and m[-1] > 2 * m[0]
    # Everything below the uplift acceleration is safe.
    assert np.all(fixed_spectrum.outcome[:, AMP < 1.0] != jr.Outcome.OVERTURNED)


def test_spectrum_as_labeled_arrays(fixed_spectrum):
    pytest.importorskip("xarray")
    s, ds = fixed_spectrum, fixed_spectrum.to_xarray()
    assert ds.outcome.dims == ("frequency_ratio", "amplitude_ratio")
    np.testing.assert_array_equal(ds.amplitude_ratio, AMP)
    for k in ("outcome", "impacts", "status"):
        np.testing.assert_array_equal(ds[k].sel(frequency_ratio=2.0), getattr(s, k)[1])
    # The lower edge, from the labels: the least overturning amplitude ratio.
    over = (ds.outcome == jr.Outcome.OVERTURNED) & (ds.status == jr.Status.SUCCESS)
    edge = ds.amplitude_ratio.where(over).min("amplitude_ratio")
    np.testing.assert_array_equal(edge, ds.minimum)
    assert float(ds.slenderness) == 4.0 and float(ds.size) == 1.0
    assert ds.attrs["base"] == "fixed base" and ds.size.attrs["units"] == "m"


def test_no_impact_edge_tends_to_linearized_closed_form():
    # Makris & Roussos's mode 2 (overturning without impact), from the closed-form
    # linearized solution: the exact edge must approach it as alpha -> 0. At
    # slenderness 20 (alpha = 0.05) 1% above it the block overturns with no
    # impact, and 1% below it does not.
    block = jr.Block(20.0, 1.0)
    ratios = np.array([0.5, 1.0, 2.0, 4.0])
    psi = jr.linearized_overturning_amplitude(ratios)
    # Closed-form limits: just above 1 for slow pulses, rising with omega_p / p.
    assert 1.0 < psi[0] < 1.2 and np.all(np.diff(psi) > 0)
    factor = np.array([0.99, 1.01])
    g_alpha = float(block.uplift_acceleration * block.alpha / np.tan(block.alpha))
    amplitude = psi[:, None] * factor * g_alpha
    frequency = np.repeat(ratios, 2) * float(block.p) / (2 * math.pi)
    motions = jr.SinePulse(amplitude.ravel(), frequency)
    bm = jr.behavior_map([20.0], [1.0], jr.FixedBase(), motions, progress=False)
    no_impact = (bm.outcome == jr.Outcome.OVERTURNED) & (bm.impacts == 0)
    assert np.all(bm.status == jr.Status.SUCCESS)
    assert np.array_equal(no_impact.reshape(4, 2), np.tile([False, True], (4, 1)))


def test_the_linearized_amplitude_of_a_long_pulse_does_not_overflow():
    """For slow pulses (omega_p / p down to 0.005) the closed form's e^tau
    overflows: the amplitude stays finite, just above 1, and warns nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        psi = jr.linearized_overturning_amplitude(np.array([0.005, 0.05, 0.5]))
    assert np.all(np.isfinite(psi)) and 1.0 < psi[0] <= psi[1] < psi[2]


def test_minimum_is_the_lowest_whatever_the_order_of_the_axis(fixed_spectrum):
    """`minimum` is the least overturning amplitude ratio of the grid, not the
    first in the order given: a reversed axis gives the same edge."""
    reversed_ = jr.overturning_spectrum(
        BLOCK, jr.FixedBase(), FREQ, AMP[::-1], progress=False
    )
    np.testing.assert_array_equal(reversed_.outcome, fixed_spectrum.outcome[:, ::-1])
    np.testing.assert_array_equal(reversed_.minimum, fixed_spectrum.minimum)


def test_overturning_spectrum_uses_the_blocks_restitution_and_friction():
    blk = jr.Block(6.0, 1.0, restitution_factor=0.5, friction=0.05)
    s = jr.overturning_spectrum(blk, jr.FixedBase(), [3.0], [1.5], progress=False)
    p, up = float(blk.p), float(blk.uplift_acceleration)
    one = jr.simulate(
        blk, jr.FixedBase(), jr.SinePulse(1.5 * up, 3.0 * p / (2 * np.pi))
    )
    assert s.status[0, 0] == int(one.status) == jr.Status.SLIDING
    assert s.outcome[0, 0] == int(one.outcome)
    assert s.impacts[0, 0] == int(one.impacts)


def test_overturning_spectrum_refuses_a_restitution_given_twice():
    blk = jr.Block(6.0, 1.0, restitution_factor=0.5)
    with pytest.raises(ValueError, match="restitution_factor"):
        jr.overturning_spectrum(
            blk, jr.FixedBase(), [3.0], [1.5], restitution_factor=0.8, progress=False
        )
