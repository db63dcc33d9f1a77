"""A paper-size map (2,440 cells) against the SciPy reference on random cells."""

import numpy as np
import pytest
import reference as ref

import jaxrock as jr

PULSE = "San Fernando PCD/SN"


@pytest.fixture(scope="module")
def paper_map():
    lam = np.round(np.arange(1.0, 7.0 + 1e-9, 0.1), 10)
    size = np.round(np.arange(0.1, 4.0 + 1e-9, 0.1), 10)
    # rtol 1e-9: at the default 1e-8 a few cells of small rocking (max rotation
    # below 1% of alpha) differ from the reference by 1.1e-6 relative.
    return jr.behavior_map(
        lam,
        size,
        jr.FixedBase(),
        jr.near_fault_pulse(PULSE),
        rtol=1e-9,
        atol=1e-11,
        progress=False,
    )


def test_random_cells_match_reference(paper_map):
    a_cm, gamma, phase, freq = jr._ground._TABLE_3_1[PULSE]
    acc, t_end, max_step = ref.mp_pulse(a_cm / 100, freq, gamma, phase)
    rng = np.random.default_rng(1)
    cells = rng.choice(paper_map.outcome.size, 100, replace=False)
    for c in cells:
        i, j = np.unravel_index(c, paper_map.outcome.shape)
        theirs = ref.simulate(
            paper_map.slenderness[i],
            paper_map.size[j],
            ("fixed",),
            acc,
            t_end + 5.0,
            max_step,
        )
        assert paper_map.status[i, j] == jr.Status.SUCCESS
        assert paper_map.outcome[i, j] == theirs["outcome"], (i, j)
        np.testing.assert_allclose(
            paper_map.max_rotation[i, j],
            theirs["max_rotation"],
            rtol=1e-6,
            atol=1e-12,
            err_msg=str((i, j)),
        )


def test_paper_map_has_every_outcome_and_threshold(paper_map):
    assert set(np.unique(paper_map.outcome)) == {0, 1, 2}
    # No cell rotates past overturning (pi / 2 = pi / (2 alpha) in max_rotation).
    alpha = np.arctan(1.0 / paper_map.slenderness)[:, None]
    assert np.all(paper_map.max_rotation <= 0.5 * np.pi / alpha * (1 + 1e-12))
    assert np.all(paper_map.status == jr.Status.SUCCESS)
    # Uplift boundary: no rocking exactly where tan(alpha) >= PGA / g.
    pulse = jr.near_fault_pulse(PULSE)
    ts = np.linspace(0.0, float(pulse.end_time), 200001)
    pga = np.max(np.abs(np.asarray(pulse.acceleration(ts))))
    calm = 1.0 / paper_map.slenderness > pga / 9.81
    np.testing.assert_array_equal(
        paper_map.outcome == 0, np.broadcast_to(calm[:, None], paper_map.outcome.shape)
    )
