"""Without a `duration`, an analysis runs until the block's fate is decided:
its outcome does not depend on a window, and a fate still open at the limit
is UNDECIDED."""

import math

import numpy as np
import pytest
import reference as ref

import jaxrock as jr

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
END = float(PULSE.end_time)
# Near the paper's overturning boundary under the San Fernando pulse, where
# blocks creep over their corner long after the pulse.
LAM = np.array([4.4, 4.9, 5.6, 5.8, 6.0])
SIZE = np.array([3.2, 3.4, 3.5, 3.7])
BASES = {
    "fixed": jr.FixedBase(),
    "linear": jr.LinearIsolator(2.0, 0.35, 0.5),
}


@pytest.mark.parametrize("name", list(BASES))
def test_the_default_outcome_is_that_of_a_longer_window(name):
    """The default map's outcomes equal those of a window 60 s longer than
    the excitation plus 5 s, where that short window reports blocks as
    rocking that overturn after it."""
    base = BASES[name]
    default = jr.behavior_map(LAM, SIZE, base, PULSE, progress=False)
    short = jr.behavior_map(LAM, SIZE, base, PULSE, duration=END + 5.0)
    long = jr.behavior_map(LAM, SIZE, base, PULSE, duration=END + 65.0)
    late = (short.outcome == jr.Outcome.ROCKING) & (
        long.outcome == jr.Outcome.OVERTURNED
    )
    assert np.sum(late) >= 1  # the window decides today's answer there
    np.testing.assert_array_equal(default.outcome, long.outcome)
    assert np.all(default.status == jr.Status.SUCCESS)
    overturned = default.outcome == jr.Outcome.OVERTURNED
    np.testing.assert_array_equal(
        default.max_rotation[overturned], long.max_rotation[overturned]
    )


def test_a_block_that_overturns_after_the_window_is_reported_overturned():
    """A block on a fixed base (lambda 6, r 3.25 m) that rocks at the end of
    the pulse plus 5 s and overturns later: `simulate` says so by default."""
    block, base = jr.Block(6.0, 3.25), jr.FixedBase()
    short = jr.simulate(block, base, PULSE, duration=END + 5.0)
    default = jr.simulate(block, base, PULSE)
    assert short.outcome == jr.Outcome.ROCKING and short.ok
    assert default.outcome == jr.Outcome.OVERTURNED and default.ok
    assert float(default.max_rotation) == pytest.approx(
        0.5 * np.pi / float(block.alpha)
    )


def test_a_fate_still_open_at_the_limit_is_undecided(monkeypatch):
    """With the decision window cut to 1 s, a block still rocking on an
    undamped isolator (which settles only after about 270 events) is
    UNDECIDED at its end, in `simulate` and in a map; one rocking on a fixed
    base below the separatrix is decided (it can no longer overturn); a
    window the user sets ends with SUCCESS."""
    monkeypatch.setattr(jr._results, "DECISION_WINDOW", 1.0)
    pulse = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.3)
    end = float(pulse.end_time)
    base, block = jr.LinearIsolator(2.0, 0.0, 0.5), jr.Block(6.0, 3.0)
    settled = jr.simulate(block, base, pulse, duration=end + 60.0)
    assert settled.outcome == jr.Outcome.ROCKING and int(settled.segments) > 200
    default = jr.simulate(block, base, pulse)
    assert default.status == jr.Status.UNDECIDED and not default.ok
    assert "UNDECIDED" in default.summary()
    cut = jr.simulate(block, base, pulse, duration=end + 1.0)
    assert cut.status == jr.Status.SUCCESS
    np.testing.assert_array_equal(cut.max_rotation, default.max_rotation)
    bm = jr.behavior_map([6.0, 1.5], [3.0], base, pulse, progress=False)
    assert bm.status[0, 0] == jr.Status.UNDECIDED
    assert bm.status[1, 0] == jr.Status.SUCCESS  # never uplifts: base quiet
    assert bm.counts()["undecided"] == 1 and "1 undecided" in bm.summary()
    slender = jr.Block(8.0, 1.0)
    fixed = jr.simulate(slender, jr.FixedBase(), pulse)
    later = jr.simulate(slender, jr.FixedBase(), pulse, duration=end + 60.0)
    assert fixed.outcome == jr.Outcome.ROCKING and fixed.ok
    assert int(later.impacts) > int(fixed.impacts)  # rocking at the limit


@pytest.mark.parametrize(
    "base",
    [jr.LinearIsolator(2.0, 0.0, 0.5), jr.FrictionPendulum(0.11, 2.24, 0.5)],
    ids=["undamped linear", "friction pendulum"],
)
def test_a_block_its_base_can_no_longer_lift_is_decided(base):
    """A block at rest on a base that still moves once the ground is still,
    too weakly ever to lift it, is decided: SUCCESS at the window's end, not
    UNDECIDED. Under a record of zeros, and under a weak pulse that leaves an
    undamped isolator swinging for ever (and a friction pendulum's base
    oscillating on its Bouc-Wen stiffness)."""
    zeros = jr.Record(np.zeros(200), 0.01)
    weak = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.01)
    block = jr.Block(4.0, 1.0)
    for motion in (zeros, weak):
        r = jr.simulate(block, base, motion)
        assert r.status == jr.Status.SUCCESS and r.outcome == jr.Outcome.NO_ROCKING
    bm = jr.behavior_map([2.0, 4.0], [0.5, 1.0], base, zeros, progress=False)
    assert np.all(bm.status == jr.Status.SUCCESS) and bm.counts()["undecided"] == 0
    assert np.all(bm.max_base_displacement == 0.0)


def test_a_block_falling_when_the_ground_stops_counts_its_next_apex():
    """A block falling when a one-sine pulse ends (the ground fed it after
    its last apex) rebounds to an apex higher than any during the pulse:
    the closed-form tail of the default analysis and of maps counts it, as
    the SciPy reference does, and a window that ends on the way up reads
    theta there, as the integrated tail does."""
    block, base, motion = jr.Block(10.0, 30.0), jr.FixedBase(), jr.SinePulse(3.0, 2.0)

    def acc(t):
        return 3.0 * math.sin(4.0 * math.pi * t) if 0.0 <= t <= 0.5 else 0.0

    theirs = ref.simulate(10.0, 30.0, ("fixed",), acc, 3.0, float(motion.max_step))
    ours = jr.simulate(block, base, motion)
    assert float(ours.max_rotation) == pytest.approx(theirs["max_rotation"], rel=1e-6)
    for duration in (None, 0.8):  # 0.8 s: before the rebound's apex
        bm = jr.behavior_map([10.0], [30.0], base, motion, duration=duration)
        window = 3.0 if duration is None else duration
        integrated = jr.simulate(block, base, motion, duration=window, history=True)
        assert float(bm.max_rotation[0, 0]) == pytest.approx(
            float(integrated.max_rotation), rel=1e-7
        )
