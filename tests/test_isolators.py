"""The Bouc-Wen isolators beside the friction pendulum: `BilinearIsolator`
(the paper's general isolator, Eqs. (2.5)-(2.6), of which the friction
pendulum is the case K = M g / R, Q = mu M g) and the rolling isolators."""

import jax
import numpy as np
import pytest

import jaxrock as jr
from jaxrock._misc import GRAVITY

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


def _same_as(pendulum: jr.FrictionPendulum) -> jr.BilinearIsolator:
    """The bilinear isolator of the pendulum's K, Q and Y."""
    period = 2.0 * np.pi * np.sqrt(float(pendulum.radius) / GRAVITY)
    return jr.BilinearIsolator(
        float(pendulum.friction),
        period,
        float(pendulum.yield_displacement),
        float(pendulum.mass_ratio),
    )


def test_a_friction_pendulum_is_the_bilinear_isolator_of_its_k_q_and_y():
    pendulum = jr.FrictionPendulum(0.11, 2.24, 0.5)
    bilinear = _same_as(pendulum)
    assert float(bilinear.stiffness_per_mass) == pytest.approx(
        float(pendulum.stiffness_per_mass), rel=1e-15
    )
    lam, size = np.array([2.5, 4.0, 5.5]), np.array([0.4, 1.0, 2.5])
    maps = [
        jr.behavior_map(lam, size, base, PULSE, progress=False)
        for base in (pendulum, bilinear)
    ]
    np.testing.assert_array_equal(maps[0].outcome, maps[1].outcome)
    np.testing.assert_array_equal(maps[0].impacts, maps[1].impacts)
    assert len(set(maps[0].outcome.ravel())) == 3  # no rocking, rocking, overturning
    for field in ("max_rotation", "max_base_displacement", "uplift_time"):
        np.testing.assert_allclose(
            getattr(maps[0], field), getattr(maps[1], field), rtol=1e-9, err_msg=field
        )


def test_the_force_is_k_u_plus_q_z():
    base = jr.BilinearIsolator(0.06, 2.5, 0.015, 0.5)
    state = base.initial_state().at[0].set(0.2)  # 0.2 m = 13 Y: z near 1
    z = float(base.hysteretic(state))
    assert 0.99 < z <= 1.0
    k = (2.0 * np.pi / 2.5) ** 2
    assert float(base.force(state)) == pytest.approx(k * 0.2 + 0.06 * GRAVITY * z)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(strength=-0.01), "strength"),
        (dict(period=0.0), "period"),
        (dict(yield_displacement=0.0), "yield_displacement"),
        (dict(mass_ratio=-1.0), "mass_ratio"),
        (dict(beta=-2.0), "beta"),
    ],
)
def test_parameters_out_of_range_are_named(kwargs, name):
    args = dict(strength=0.06, period=2.5, yield_displacement=0.015, mass_ratio=0.5)
    with pytest.raises(ValueError, match=f"`{name}`"):
        jr.BilinearIsolator(**(args | kwargs))


def test_a_spherical_rolling_isolator_is_a_rolling_pendulum():
    """Balls in spherical dishes: a friction pendulum whose friction is the
    rolling resistance."""
    sphere = jr.SphericalRollingIsolator(1.2, 0.005, 1.0)
    pendulum = jr.FrictionPendulum(0.005, 1.2, 1.0)
    lam, size = np.array([3.0, 5.0]), np.array([0.5, 2.0])
    maps = [
        jr.behavior_map(lam, size, base, PULSE, progress=False)
        for base in (pendulum, sphere)
    ]
    np.testing.assert_array_equal(maps[0].outcome, maps[1].outcome)
    np.testing.assert_allclose(maps[0].max_rotation, maps[1].max_rotation, rtol=1e-9)
    np.testing.assert_allclose(
        maps[0].max_base_displacement, maps[1].max_base_displacement, rtol=1e-9
    )


def test_a_cones_force_is_its_potentials_slope_and_never_exceeds_g_s():
    cone = jr.ConicalRollingIsolator(0.08, 0.004, 1.0, apex=2e-3)
    u = np.array([-0.5, -0.01, -1e-4, 0.0, 3e-4, 0.002, 0.3, 2.0])
    slope = jax.vmap(jax.grad(cone.potential))(u)
    np.testing.assert_allclose(slope, cone.restoring_force(u), rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(cone.restoring_force(u)) < GRAVITY * 0.08)
    assert float(cone.restoring_force(2.0)) == pytest.approx(GRAVITY * 0.08, rel=1e-6)
    # The bound of |u| at a potential energy is where that energy is reached.
    np.testing.assert_allclose(
        cone.displacement_bound(cone.potential(u)), np.abs(u), rtol=1e-9, atol=1e-12
    )


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: jr.SphericalRollingIsolator(0.0, 0.005, 1.0), "radius"),
        (lambda: jr.SphericalRollingIsolator(1.0, -0.1, 1.0), "rolling_resistance"),
        (lambda: jr.ConicalRollingIsolator(0.0, 0.005, 1.0), "slope"),
        (lambda: jr.ConicalRollingIsolator(0.1, 0.005, 1.0, apex=0.0), "apex"),
    ],
)
def test_rolling_isolator_parameters_out_of_range_are_named(make, name):
    with pytest.raises(ValueError, match=f"`{name}`"):
        make()


@pytest.mark.parametrize(
    "make",
    [
        lambda g, b: jr.BilinearIsolator(0.05, 2.5, 0.015, 0.5, gamma=g, beta=b),
        lambda g, b: jr.FrictionPendulum(0.11, 2.24, 0.5, gamma=g, beta=b),
        lambda g, b: jr.SphericalRollingIsolator(1.5, 0.005, 0.5, gamma=g, beta=b),
        lambda g, b: jr.ConicalRollingIsolator(0.1, 0.005, 0.5, gamma=g, beta=b),
        lambda g, b: jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, gamma=g, beta=b),
    ],
)
def test_a_negative_gamma_is_refused(make):
    """With gamma < 0 (and gamma + beta > 0) Bouc-Wen's z is unbounded: a
    reversal from |z| near (A / (gamma + beta))^(1/eta) makes |z| grow on the
    beta - gamma branch without end (a simulation ran to MAX_STEPS). gamma
    must be >= 0, named in the error."""
    with pytest.raises(ValueError, match="`gamma` must be finite and >= 0"):
        make(-0.2, 0.3)
    make(0.0, 0.3)  # gamma = 0: z stays within (A / beta)^(1/eta)


@pytest.mark.parametrize("eta", [np.array([1.0, 2.0]), "x", True, None])
def test_a_bad_eta_is_named(eta):
    with pytest.raises(ValueError, match="`eta`"):
        jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=eta)


def test_a_traced_eta_is_named():
    with pytest.raises(ValueError, match="`eta` is static"):
        jax.jit(
            lambda e: jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=e).friction
        )(1.5)


def test_good_etas_are_python_floats():
    for eta in (1, 1.5, np.float64(2.5)):
        base = jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=eta)
        assert type(base.eta) is float and base.eta == float(eta)
