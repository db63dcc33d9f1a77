"""Overturning spectra under one-sine pulses, checked against the SciPy reference."""

import math

import numpy as np
import pytest
import reference as ref

import jaxrock as jr
from jaxrock.cli import main

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


def test_cli_spectrum(tmp_path, capsys):
    out = tmp_path / "s.png"
    assert (
        main(
            [
                "spectrum",
                "--frequency-ratio",
                "1:4:3",
                "--amplitude-ratio",
                "1:5:5",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert out.stat().st_size > 10_000
    assert "minimum" in capsys.readouterr().out
