"""The step-size controller against Diffrax's PIDController at its defaults, and
the ends of steps at a motion's kinks."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock._controller import StepSizeController
from jaxrock._scene import prepare


def _decide(controller, t0, t1, y0, y1, y_error, error_order):
    _, state = controller.init(None, t0, t1, y0, t1 - t0, None, None, error_order)
    keep, next_t0, next_t1, _, _, result = controller.adapt_step_size(
        t0, t1, y0, y1, None, y_error, error_order, state
    )
    return keep, next_t0, next_t1, result


@pytest.mark.parametrize("dtmax", [None, 0.004])
def test_steps_are_those_of_diffrax_pid_controller(dtmax):
    # Errors from 1e-9 to 1e9 times the tolerance: kept and rejected steps,
    # and factors at both clips and between.
    rng = np.random.default_rng(0)
    n = 4000
    y0 = (rng.normal(size=n), rng.normal(size=n))
    y1 = (y0[0] + 1e-3 * rng.normal(size=n), y0[1] + 1e-3 * rng.normal(size=n))
    scale = 10.0 ** rng.uniform(-9, 9, size=n)
    y_error = (1e-10 * scale * rng.normal(size=n), 1e-10 * scale * rng.normal(size=n))
    t0, t1 = jnp.full(n, 0.5), jnp.full(n, 0.51)
    kw = dict(rtol=1e-8, atol=1e-10, dtmax=dtmax)
    ours, pid = StepSizeController(**kw), diffrax.PIDController(**kw)
    decide = jax.vmap(_decide, in_axes=(None, 0, 0, 0, 0, 0, None))
    got = decide(ours, t0, t1, y0, y1, y_error, 5.0)
    want = decide(pid, t0, t1, y0, y1, y_error, 5.0)
    np.testing.assert_array_equal(got[0], want[0])  # kept
    assert 0 < np.mean(got[0]) < 1
    np.testing.assert_array_equal(got[1], want[1])  # the next step's start
    # The next step's end: exp(log) against a power, within rounding.
    dt_got, dt_want = np.asarray(got[2] - got[1]), np.asarray(want[2] - want[1])
    np.testing.assert_allclose(dt_got, dt_want, rtol=1e-13, atol=0)
    assert bool(jnp.all(got[3] == diffrax.RESULTS.successful))


def test_a_nan_error_rejects_the_step():
    controller = StepSizeController(rtol=1e-8, atol=1e-10)
    y0, y1 = (jnp.asarray(1.0),), (jnp.asarray(jnp.nan),)
    keep, next_t0, _, _ = _decide(
        controller, 0.0, 0.01, y0, y1, (jnp.asarray(jnp.nan),), 5.0
    )
    assert not bool(keep) and float(next_t0) == 0.0


def test_steps_to_a_sample_are_equal_and_end_on_it():
    record = prepare(jr.Record(np.zeros(100), dt=0.01))
    t0 = 0.0133
    kink = float(record.next_kink(jnp.asarray(t0)))
    assert kink == 0.02
    # 3 equal steps where the controller proposes 0.0025 s (ceil(0.0067 / 0.0025)).
    t1 = float(record.step_end(t0, 0.0025, kink))
    assert t1 == pytest.approx(t0 + (kink - t0) / 3, rel=1e-15)
    assert float(record.step_end(t0, 0.05, kink)) == kink  # exactly the sample
    # Far from the sample (more than 8 steps): the proposal.
    assert float(record.step_end(t0, 0.0005, kink)) == t0 + 0.0005


def test_a_closed_form_bound_cuts_the_step_without_equal_steps():
    pulse = prepare(jr.near_fault_pulse("Northridge JFA/SN"))
    assert float(pulse.step_end(0.0, 0.0025, 0.0067)) == 0.0025
    assert float(pulse.step_end(0.0, 0.01, 0.0067)) == 0.0067
