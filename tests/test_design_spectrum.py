"""Design spectra: ASCE 7-22 and Eurocode 8 at their corners, continuous
across them, and bad parameters named."""

import numpy as np
import pytest

import jaxrock as jr


def test_asce7_spectrum_corners_and_branches():
    sds, sd1, tl = 1.2, 0.5, 6.0
    t0, ts = 0.2 * sd1 / sds, sd1 / sds
    t = np.array([1e-6, t0, ts, 1.0, tl, 2 * tl])
    got = jr.asce7_spectrum(t, sds=sds, sd1=sd1, tl=tl)
    want = [sds * (0.4 + 0.6e-6 / t0), sds, sds, sd1, sd1 / tl, sd1 / (4 * tl)]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # Continuous at every corner, and nowhere above S_DS.
    for corner in (t0, ts, tl):
        side = jr.asce7_spectrum(
            [corner * (1 - 1e-9), corner * (1 + 1e-9)], sds, sd1, tl
        )
        np.testing.assert_allclose(side[0], side[1], rtol=1e-8)
    grid = np.geomspace(0.01, 20.0, 500)
    assert jr.asce7_spectrum(grid, sds, sd1, tl).max() <= sds


@pytest.mark.parametrize("spectrum_type", [1, 2])
@pytest.mark.parametrize("ground", list("ABCDE"))
def test_eurocode8_spectrum_corners(spectrum_type, ground):
    s, tb, tc, td = {
        1: {
            "A": (1.0, 0.15, 0.4, 2.0),
            "B": (1.2, 0.15, 0.5, 2.0),
            "C": (1.15, 0.2, 0.6, 2.0),
            "D": (1.35, 0.2, 0.8, 2.0),
            "E": (1.4, 0.15, 0.5, 2.0),
        },
        2: {
            "A": (1.0, 0.05, 0.25, 1.2),
            "B": (1.35, 0.05, 0.25, 1.2),
            "C": (1.5, 0.1, 0.25, 1.2),
            "D": (1.8, 0.1, 0.3, 1.2),
            "E": (1.6, 0.05, 0.25, 1.2),
        },
    }[spectrum_type][ground]  # EN 1998-1 Tables 3.2 and 3.3
    ag = 2.5
    got = jr.eurocode8_spectrum(
        [1e-9, tb, tc, td, 2 * td], ag, ground_type=ground, spectrum_type=spectrum_type
    )
    plateau = 2.5 * ag * s
    np.testing.assert_allclose(
        got,
        [
            ag * s * (1 + 1.5e-9 / tb),
            plateau,
            plateau,
            plateau * tc / td,
            plateau * tc / (4 * td),
        ],
        rtol=1e-8,
    )
    # 10% damping: eta = sqrt(10 / 15) on the plateau.
    ten = jr.eurocode8_spectrum(tc, ag, ground, spectrum_type, damping=0.10)
    np.testing.assert_allclose(ten, plateau * np.sqrt(10 / 15), rtol=1e-12)
    # eta is at least 0.55 (damping above 28%).
    high = jr.eurocode8_spectrum(tc, ag, ground, spectrum_type, damping=0.5)
    np.testing.assert_allclose(high, plateau * 0.55, rtol=1e-12)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: jr.asce7_spectrum([0.0, 1.0], 1.0, 0.6, 8.0), "`periods` must be"),
        (lambda: jr.asce7_spectrum(1.0, np.nan, 0.6, 8.0), "`sds` must be one finite"),
        (lambda: jr.asce7_spectrum(1.0, 1.0, -0.6, 8.0), "`sd1` must be one finite"),
        (lambda: jr.asce7_spectrum(1.0, 1.0, 0.6, 0.5), "`tl` must exceed T_S"),
        (lambda: jr.eurocode8_spectrum(1.0, 0.0), "`ag` must be one finite"),
        (lambda: jr.eurocode8_spectrum(1.0, 2.0, "F"), "`ground_type` must be one"),
        (lambda: jr.eurocode8_spectrum(1.0, 2.0, "B", 3), "`spectrum_type` must be 1"),
        (lambda: jr.eurocode8_spectrum(1.0, 2.0, damping=1.0), "`damping` must be > 0"),
        # Unhashable values are named too, not a bare TypeError.
        (lambda: jr.eurocode8_spectrum(1.0, 2.0, ["B"]), "`ground_type` must be one"),
        (
            lambda: jr.eurocode8_spectrum(1.0, 2.0, "B", [1]),
            "`spectrum_type` must be 1",
        ),
    ],
)
def test_design_spectra_name_bad_parameters(call, message):
    with pytest.raises(ValueError, match=message):
        call()
