"""The flat loop: its unrolled Runge-Kutta step against Diffrax's own step, and
the event conditions it carries from step to step."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock._dynamics import Args, Phase, vector_field
from jaxrock._flat import _dense_in_s, _erk_step
from jaxrock._misc import computed_once
from jaxrock._scene import prepare


def _rising(base):
    """Arguments of a block (3.0, 1.0 m) rising about x = +b mid-pulse."""
    return Args(
        jr.Block(3.0, 1.0),
        base,
        prepare(jr.near_fault_pulse("San Fernando PCD/SN")),
        jnp.asarray(Phase.RISING),
        jnp.asarray(1.0),
        jnp.asarray(0.0),
        jnp.asarray(False),
        jnp.asarray(0.0),
    )


@pytest.mark.parametrize("solver", [diffrax.Tsit5(), diffrax.Dopri5()])
def test_unrolled_step_equals_diffrax_step(solver):
    """Same y1, error estimate and dense output (so the same interpolant), on a
    rocking block on a friction pendulum mid-pulse (all five states moving)."""
    base = jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=3.0)  # z integrated
    args = _rising(base)
    y0 = (jnp.asarray(0.01), jnp.asarray(0.2), jnp.array([0.01, 0.3, 0.5]))
    t0, t1 = jnp.asarray(0.7), jnp.asarray(0.7001)
    term = diffrax.ODETerm(vector_field)
    state = solver.init(term, t0, t1, y0, args)
    want = solver.step(term, t0, t1, y0, args, state, made_jump=False)[:3]
    got = _erk_step(solver.tableau, t0, t1, y0, args)
    for w, g in zip(jax.tree_util.tree_leaves(want), jax.tree_util.tree_leaves(got)):
        np.testing.assert_allclose(np.asarray(g), np.asarray(w), rtol=1e-13, atol=1e-17)
    ts = jnp.linspace(t0, t1, 5)
    for t in ts:
        a = solver.interpolation_cls(t0=t0, t1=t1, **want[2]).evaluate(t)
        b = solver.interpolation_cls(t0=t0, t1=t1, **got[2]).evaluate(t)
        for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
            np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=1e-13)


def test_computed_once_is_exact_and_transparent_to_derivatives():
    """The fusion boundary divides by 1.0: bit-identical values (signed zeros,
    infinities, NaN, integers untouched) under jit and vmap, identity tangents."""
    x = jnp.array([0.0, -0.0, 1e-300, -3.7, 1e300, jnp.inf, -jnp.inf, jnp.nan, 0.1])
    n = jnp.arange(9)
    got_x, got_n = jax.jit(jax.vmap(computed_once))((x, n))
    np.testing.assert_array_equal(np.asarray(got_x), np.asarray(x))
    assert np.array_equal(np.signbit(np.asarray(got_x)), np.signbit(np.asarray(x)))
    assert got_n.dtype == n.dtype and np.array_equal(np.asarray(got_n), np.arange(9))
    finite = x[jnp.isfinite(x)]
    _, tangent = jax.jvp(computed_once, (finite,), (jnp.full_like(finite, 2.5),))
    np.testing.assert_array_equal(np.asarray(tangent), 2.5)


@pytest.mark.parametrize("solver", [diffrax.Tsit5(), diffrax.Dopri8()])
def test_dense_output_in_monomials_equals_diffrax(solver):
    """The root find's interpolant (a polynomial in s, Horner's rule: a quartic
    for Tsit5, a sextic for Dopri8) is Diffrax's, with its derivative, on a
    10 ms step of a rocking block on a linear isolator mid-pulse."""
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    args = _rising(base)
    y0 = (jnp.asarray(0.01), jnp.asarray(0.2), jnp.array([0.01, 0.3]))
    t0, t1 = jnp.asarray(0.7), jnp.asarray(0.71)
    _, _, dense = _erk_step(solver.tableau, t0, t1, y0, args)

    class Step:  # what `_dense_in_s` reads of an attempt
        pass

    step = Step()
    step.t0, step.t1, step.dense = t0, t1, dense
    ours = _dense_in_s(solver, step)
    theirs = solver.interpolation_cls(t0=t0, t1=t1, **dense).evaluate
    for s in np.linspace(0.0, 1.0, 7):
        s = jnp.asarray(s)
        a, da = jax.jvp(ours, (s,), (jnp.ones_like(s),))
        b, db = jax.jvp(lambda s: theirs(t0 + s * (t1 - t0)), (s,), (jnp.ones_like(s),))
        for x, y in zip(
            jax.tree_util.tree_leaves((a, da)), jax.tree_util.tree_leaves((b, db))
        ):
            np.testing.assert_allclose(
                np.asarray(x), np.asarray(y), rtol=1e-13, atol=1e-16
            )
    # Not a copy of the other: the interpolant moves within the step.
    assert abs(float(ours(jnp.asarray(0.5))[1]) - float(y0[1])) > 1e-4


def test_carried_start_conditions_are_the_conditions_at_the_carry():
    """On a friction pendulum the flat loop carries the event conditions at
    each lane's (t, y) from the end of its last step (or from its event
    batch): at every step they are the conditions evaluated afresh, to the
    last bits, through steps that only move on and through events."""
    from jaxrock._flat import flat_step
    from jaxrock._model import initial_carry, is_active, with_start_conditions
    from jaxrock._results import SolverOptions

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 4.0, 0.01)
    record = prepare(jr.Record(6.0 * np.sin(15.0 * t) + rng.normal(size=t.size), 0.01))
    base = jr.FrictionPendulum(0.1, 2.0, 0.5)
    blocks = jr.Block(jnp.linspace(3.0, 8.0, 8), jnp.linspace(0.5, 2.5, 8))
    opts = SolverOptions.for_motion(record.record, 1e-8, 1e-10, None, 400, 1e-6, None)
    axes = (0, None, None)

    def step(c, _):
        new, _ = flat_step(c, blocks, base, record, 6.0, opts, axes)
        fresh = jax.vmap(with_start_conditions, in_axes=(0,) + axes)(
            new, blocks, base, record
        )
        apart = [
            jnp.abs(carried - now) > 1e-13 * jnp.abs(now) + 1e-15
            for carried, now in zip(new.start_conditions, fresh.start_conditions)
        ]
        return new, jnp.sum(is_active(new, opts) & sum(apart))

    c = jax.vmap(initial_carry, in_axes=axes)(blocks, base, record)
    c, apart = jax.jit(lambda c: jax.lax.scan(step, c, None, length=3000))(c)
    assert int(jnp.sum(apart)) == 0
    assert int(jnp.sum(c.impacts)) > 30 and int(jnp.sum(c.segments)) > 200


def test_a_records_step_reads_the_line_between_its_samples():
    # A step of the flat loop ends at the next sample: its stages read the
    # line between the two samples around it, as `acceleration` does at each.
    rng = np.random.default_rng(3)
    record = prepare(jr.Record(rng.normal(size=50), 0.02))
    c = np.asarray(diffrax.Tsit5().tableau.c)
    read = jax.jit(lambda ts: jnp.stack(record.step_accelerations(list(ts))))
    exact = jax.jit(jax.vmap(record.acceleration))
    for t0, t1 in [(0.0, 0.02), (0.1, 0.113), (0.113, 0.12), (0.97, 0.98), (0.98, 1.5)]:
        ts = np.concatenate([[t0], t0 + c * (t1 - t0), [t1]])
        np.testing.assert_allclose(read(ts), exact(ts), rtol=1e-13, atol=1e-13)
    # A longer step (a block at rest on a fixed base) reads its end exactly;
    # past the record's end x_g'' is 0.
    ts = np.array([0.1, 0.2, 0.35, 0.5])
    assert read(ts)[-1] == exact(ts)[-1] != 0.0
    assert read(ts)[0] == pytest.approx(float(exact(ts)[0]), abs=1e-13)
    assert np.all(read(np.array([1.0, 1.2, 1.4])) == 0.0)
