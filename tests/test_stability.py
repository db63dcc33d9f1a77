"""Where numerical methods fail, and how jaxrock detects it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference as ref
from scipy.optimize import brentq

import jaxrock as jr
from jaxrock import _simulate
from jaxrock._misc import GRAVITY
from jaxrock._solvers import RK4

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
A, FREQ, GAMMA, PHASE = 1.15, 0.68, 1.6, 180.0


def test_bouc_wen_stiffness_drives_the_step_count_and_limits_are_reported():
    """Smaller yield displacement Y = stiffer z: with z integrated (eta != 2)
    the explicit step count grows about as 1/Y; with eta = 2, z in closed form,
    it hardly moves. A segment that runs out of steps says so in `status`."""
    block = jr.Block(2.0, 1.0)  # never rocks: the base alone
    steps = {}
    for eta in (2.0, 3.0):
        for y in (5e-4, 5e-5):
            if eta == 2.0:  # z in closed form
                base = jr.FrictionPendulum(0.11, 2.24, 0.5, yield_displacement=y)
            else:
                base = jr.IntegratedFrictionPendulum(
                    0.11, 2.24, 0.5, yield_displacement=y, eta=eta
                )
            r = jr.simulate(block, base, PULSE)
            assert int(r.status) == jr.Status.SUCCESS
            steps[eta, y] = int(r.steps)
    assert steps[3.0, 5e-5] > 3 * steps[3.0, 5e-4]
    assert steps[2.0, 5e-5] < 1.5 * steps[2.0, 5e-4]
    assert 3 * steps[2.0, 5e-4] < steps[3.0, 5e-4]
    capped = jr.simulate(
        block,
        jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=3.0),
        PULSE,
        max_steps=200,
    )
    assert int(capped.status) == jr.Status.MAX_STEPS
    assert not bool(capped.ok) and "not converged" in capped.summary()


def test_zeno_without_rest_rule_hits_the_segment_limit():
    """Free rocking with rest_tolerance = 0: impacts pile up in finite time."""
    block, base = jr.Block(6.0, 2.0), jr.FixedBase()
    zeno = jr.simulate(
        block, base, PULSE, duration=40.0, rest_tolerance=0.0, max_segments=400
    )
    assert int(zeno.status) == jr.Status.MAX_SEGMENTS
    ruled = jr.simulate(block, base, PULSE, duration=40.0)
    assert int(ruled.status) == jr.Status.SUCCESS
    # The threshold changes neither the outcome nor the max rotation beyond 1e-9.
    for tol in (1e-8, 1e-4):
        other = jr.simulate(block, base, PULSE, duration=40.0, rest_tolerance=tol)
        assert int(other.outcome) == int(ruled.outcome)
        assert float(other.max_rotation) == pytest.approx(
            float(ruled.max_rotation), rel=1e-9
        )


@pytest.mark.parametrize(
    "lam, size, scale",
    [
        (20.0, 1.0, 0.3),  # very slender: alpha = 0.05 rad
        (4.0, 0.05, 1.0),  # very small: p = 12 rad/s
        (0.6, 1.0, 4.5),  # very squat: e < 0 (Eq. 2.13), every impact ends rocking
    ],
)
@pytest.mark.parametrize("base_key", ["fixed", "linear"])
def test_extremes_of_the_grid_match_reference(lam, size, scale, base_key):
    bases = {
        "fixed": (jr.FixedBase(), ("fixed",)),
        "linear": (jr.LinearIsolator(2.0, 0.35, 0.5), ("linear", 2.0, 0.35, 0.5)),
    }
    base, ref_base = bases[base_key]
    ours = jr.simulate(
        jr.Block(lam, size),
        base,
        jr.MPPulse(A * scale, FREQ, GAMMA, PHASE),
        rtol=1e-10,
        atol=1e-12,
    )
    acc, t_end, max_step = ref.mp_pulse(A * scale, FREQ, GAMMA, PHASE)
    theirs = ref.simulate(lam, size, ref_base, acc, t_end + 5.0, max_step)
    assert int(ours.status) == jr.Status.SUCCESS
    assert int(ours.outcome) == theirs["outcome"]
    assert int(ours.impacts) == theirs["impacts"]
    np.testing.assert_allclose(
        float(ours.max_rotation), theirs["max_rotation"], rtol=1e-6, atol=1e-12
    )
    if lam < 1:
        assert int(ours.outcome) != jr.Outcome.NO_ROCKING  # the case must rock
        e, _ = jr._dynamics.restitution(jr.Block(lam, size), base)
        assert float(e) < 0
        # e < 0: no impact re-uplifts; each one ends rocking (a log of rests).
        assert all(after[1] == 0.0 for after in theirs["impact_log"])


def test_near_overturn_bracket():
    """Amplitudes bracketing the overturning threshold: max |theta| approaches
    and passes alpha; both sides agree with the reference."""
    lam, size = 5.0, 1.0
    outcomes = []
    for scale in np.linspace(0.6, 1.0, 5):
        ours = jr.simulate(
            jr.Block(lam, size),
            jr.FixedBase(),
            jr.MPPulse(A * scale, FREQ, GAMMA, PHASE),
            rtol=1e-10,
            atol=1e-12,
        )
        acc, t_end, max_step = ref.mp_pulse(A * scale, FREQ, GAMMA, PHASE)
        theirs = ref.simulate(lam, size, ("fixed",), acc, t_end + 5.0, max_step)
        assert int(ours.outcome) == theirs["outcome"]
        np.testing.assert_allclose(
            float(ours.max_rotation), theirs["max_rotation"], rtol=1e-6
        )
        outcomes.append((int(ours.outcome), float(ours.max_rotation)))
    kinds = [o for o, _ in outcomes]
    assert jr.Outcome.ROCKING in kinds and jr.Outcome.OVERTURNED in kinds
    survived = [rot for o, rot in outcomes if o == jr.Outcome.ROCKING]
    assert max(survived) > 0.5  # a close call is among them


def test_record_with_long_quiet_tail():
    """A record padded with 30 s of zeros: the same answer in a 40 s window as
    in the 8 s one, and the maps over it (which never step across a sample)
    agree with `simulate` (one solve per segment), cell by cell."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 4.0, 0.01)
    acc = 6.0 * np.sin(2 * np.pi * 1.2 * t) * np.exp(-0.5 * t) + rng.normal(
        0, 0.3, t.size
    )
    padded = jr.Record(np.concatenate([acc, np.zeros(3000)]), 0.01)
    for base in (jr.FixedBase(), jr.LinearIsolator(2.0, 0.35, 0.5)):
        a = jr.simulate(jr.Block(4.0, 1.0), base, padded, duration=8.0)
        b = jr.simulate(jr.Block(4.0, 1.0), base, padded, duration=40.0)
        assert int(a.status) == int(b.status) == jr.Status.SUCCESS
        assert int(a.outcome) == int(b.outcome) and int(a.impacts) == int(b.impacts)
        assert float(b.max_rotation) == pytest.approx(float(a.max_rotation), rel=1e-7)
    lam, size, base = [2.5, 4.0], [0.5, 1.5], jr.LinearIsolator(2.0, 0.35, 0.5)
    bm = jr.behavior_map(lam, size, base, padded, duration=8.0)
    for i, j in np.ndindex(2, 2):
        one = jr.simulate(jr.Block(lam[i], size[j]), base, padded, duration=8.0)
        assert bm.outcome[i, j] == int(one.outcome)
        assert bm.impacts[i, j] == int(one.impacts)
        assert bm.max_rotation[i, j] == pytest.approx(float(one.max_rotation), rel=1e-6)
    assert set(bm.outcome.ravel()) >= {jr.Outcome.NO_ROCKING, jr.Outcome.ROCKING}


def test_naive_fixed_step_baseline_is_wrong_and_default_is_not():
    """RK4 at a fixed 10 ms step with events at step ends only (the baseline of the
    work-precision study) misses the impacts that the default locates."""
    block, base = jr.Block(3.0, 2.0), jr.LinearIsolator(2.0, 0.35, 0.5)
    duration = jr._misc.as_float(float(PULSE.end_time) + 5.0)
    naive = _simulate._run_jit(
        block, base, PULSE, duration, jr.SolverOptions(step=0.01, solver=RK4())
    )
    good = jr.simulate(block, base, PULSE)
    tight = jr.simulate(block, base, PULSE, rtol=1e-11, atol=1e-13)
    assert int(good.impacts) == int(tight.impacts)
    assert float(good.max_rotation) == pytest.approx(
        float(tight.max_rotation), rel=1e-5
    )
    assert abs(float(naive.max_rotation) / float(tight.max_rotation) - 1) > 0.1
    assert int(naive.impacts) != int(tight.impacts)


def test_near_double_root_of_theta_dot_is_caught():
    """Northridge JFA, linear isolator, lambda = 6, r = 1.1 m: an apex where theta'
    only touches zero once sent the block past pi/2 unwatched (max rotation 27.7
    alpha, outcome "rocking") in some batches. The guard condition catches it; the
    answer no longer depends on the batch and matches the reference."""
    pulse = jr.near_fault_pulse("Northridge JFA/SN")
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    sizes = np.round(np.arange(0.1, 4.0 + 1e-9, 0.1), 10)
    acc, t_end, max_step = ref.mp_pulse(0.87, 0.33, 2.3, 100.0)
    theirs = ref.simulate(
        6.0, 1.1, ("linear", 2.0, 0.35, 0.5), acc, t_end + 5.0, max_step
    )
    j = int(np.flatnonzero(sizes == 1.1)[0])
    # Two batchings (chunk shapes other tests compile too: 4 and 64 lanes).
    for chunk in (4, None):
        bm = jr.behavior_map([6.0], sizes, base, pulse, chunk_size=chunk)
        assert bm.outcome[0, j] == theirs["outcome"] == jr.Outcome.OVERTURNED
        # Never a rotation past overturning in any cell.
        assert np.all(bm.max_rotation <= 0.5 * np.pi / np.arctan(1 / 6.0) + 1e-9)


def test_block_at_rest_under_a_pulse_steps_to_its_uplift_by_the_level_bound():
    """A block at rest on a fixed base: its steps end before |x_g''| could
    reach g tan(alpha) (the pulse's curvature bound), with no other step
    limit. Its uplift is where a dense search of |x_g''| finds it, a level
    just above the peak never uplifts, and either takes fewer steps than
    the pulse lasts in steps of `max_step`."""
    pulse = jr.MPPulse(2.0, 1.5, 2.0, 90.0)
    t = np.linspace(0.0, float(pulse.end_time), 400_001)
    a = np.abs(np.asarray(jax.vmap(pulse.acceleration)(jnp.asarray(t))))
    peak = a.max()
    limit_steps = float(pulse.end_time / pulse.max_step)
    for share in (0.97, 0.9995, 1.0005):
        lam = GRAVITY / (share * peak)  # g tan(alpha) = share * peak
        r = jr.simulate(jr.Block(lam, 1.0), jr.FixedBase(), pulse)
        assert int(r.steps) < limit_steps
        if share > 1:
            assert int(r.outcome) == jr.Outcome.NO_ROCKING
            continue
        k = np.flatnonzero(a >= share * peak)[0]
        root = brentq(
            lambda s: abs(float(pulse.acceleration(s))) - share * peak, t[k - 1], t[k]
        )
        assert float(r.uplift_time) == pytest.approx(root, abs=1e-9)


@pytest.mark.parametrize("t, lifts", [(0.70, True), (0.50, False)])
def test_a_block_that_settles_while_the_ground_lifts_it_uplifts_at_once(t, lifts):
    """A block rising on its corner -b whose apex comes at theta <= 0 (a
    rebound too small, the ground swinging the other way) settles on its
    base. Where |x_g''| then reaches g tan(alpha) (at 0.70 s of the San
    Fernando pulse, x_g'' = -2.18 m/s^2 against 1.53), it rocks on its
    corner +b at once: its uplift conditions start at <= 0 there and would
    never fire. Below the level (0.50 s, 0.98 m/s^2) it stays at rest."""
    import diffrax
    import equinox as eqx

    from jaxrock._dynamics import Phase
    from jaxrock._flat import _StepSolution
    from jaxrock._model import initial_carry, transition
    from jaxrock._results import SolverOptions
    from jaxrock._scene import prepare

    block, base, motion = jr.Block(6.4, 0.2), jr.FixedBase(), prepare(PULSE)
    opts = SolverOptions.for_motion(PULSE, 1e-8, 1e-10, 100_000, 400, 1e-6, None)
    level = GRAVITY / 6.4
    assert (abs(float(PULSE.acceleration(t))) >= level) == lifts
    c = initial_carry(block, base, motion)
    c = eqx.tree_at(
        lambda c: (c.t, c.phase, c.sign, c.rocked),
        c,
        (jnp.asarray(t - 1e-3), Phase.RISING, jnp.asarray(-1.0), jnp.asarray(True)),
    )
    y = (jnp.asarray(1e-12), jnp.asarray(0.0), None)  # the apex, -b theta < 0
    fired = (jnp.asarray(False), jnp.asarray(True), jnp.asarray(False))
    sol = _StepSolution(
        jnp.asarray(t), y, diffrax.RESULTS.event_occurred, fired, jnp.asarray(1)
    )
    new = transition(c, sol, block, base, motion, 10.0, opts)
    assert float(new.t) == t and float(new.y[0]) == 0.0
    if lifts:
        assert int(new.phase) == Phase.RISING and float(new.sign) == 1.0
    else:
        assert int(new.phase) == Phase.TRANSLATION
