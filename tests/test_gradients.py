"""Forward-mode derivatives through the whole segment loop, against finite differences.

Central differences of the same function with a relative step h = 1e-5, both at
rtol 1e-12 / atol 1e-14 (so that solver noise, about 1e-12 / h = 1e-7, stays below
the 1e-5 tolerance); only cases whose impact count and outcome do not change
inside the stencil are compared (there the response is smooth).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _design

TOL = dict(rtol=1e-12, atol=1e-14)
PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


def _linear(period):
    return jr.simulate(
        jr.Block(3.0, 0.5), jr.LinearIsolator(period, 0.35, 0.5), PULSE, **TOL
    )


def _fps(friction):
    return jr.simulate(
        jr.Block(4.0, 1.0), jr.FrictionPendulum(friction, 2.24, 0.5), PULSE, **TOL
    )


def _fixed(amplitude):
    return jr.simulate(
        jr.Block(6.0, 2.0),
        jr.FixedBase(),
        jr.MPPulse(amplitude, 0.68, 1.6, 180.0),
        **TOL,
    )


def _linear_damping(damping):
    return jr.simulate(
        jr.Block(3.0, 0.5), jr.LinearIsolator(2.0, damping, 0.5), PULSE, **TOL
    )


def _bilinear_period(period):
    base = jr.BilinearIsolator(0.06, period, 0.015, 0.5)
    return jr.simulate(jr.Block(3.0, 0.5), base, PULSE, **TOL)


def _bilinear_strength(strength):
    base = jr.BilinearIsolator(strength, 2.5, 0.015, 0.5)
    return jr.simulate(jr.Block(3.0, 0.5), base, PULSE, **TOL)


FUNCTIONS = {
    "bilinear-period": _bilinear_period,
    "bilinear-strength": _bilinear_strength,
    "linear-period": _linear,
    "linear-damping": _linear_damping,
    "fps-friction": _fps,
    "fixed-amplitude": _fixed,
}


@functools.cache
def _derivatives(name, x0):
    """jaxrock's d(max_rotation, max_base_displacement)/dx: one trace and compile
    per function, shared by the tests below (compiling is most of their time)."""
    f = FUNCTIONS[name]
    d = jax.jacfwd(
        lambda x: (lambda r: (r.max_rotation, r.max_base_displacement))(f(x))
    )
    rotation, displacement = d(jnp.asarray(x0))
    return {
        "max_rotation": float(rotation),
        "max_base_displacement": float(displacement),
    }


# name -> (function, point, field, relative tolerance)
CASES = {
    "linear-period": (_linear, 2.0, "max_rotation", 1e-5),
    "linear-period-disp": (_linear, 2.0, "max_base_displacement", 1e-5),
    # Bouc-Wen's |u'| has a kink at every velocity reversal, inside a step; the
    # derivative of the discrete solution there carries an error of the order of
    # that step (measured: 5.8e-5 relative; the differences converge to 3e-8
    # for h from 1e-3 to 1e-5, so the gap is in the derivative, not in them).
    "fps-friction": (_fps, 0.11, "max_rotation", 1e-4),
    "bilinear-period": (_bilinear_period, 2.5, "max_rotation", 1e-4),
    "bilinear-strength": (_bilinear_strength, 0.06, "max_rotation", 1e-4),
    "fixed-amplitude": (_fixed, 1.15, "max_rotation", 1e-5),
}


@pytest.mark.parametrize("name", list(CASES))
def test_jacfwd_matches_central_differences(name):
    f, x0, field, rel = CASES[name]
    h = 1e-5 * x0
    lo, mid, hi = f(x0 - h), f(x0), f(x0 + h)
    assert int(mid.impacts) >= 2, "the case must rock with several impacts"
    for r in (lo, hi):
        assert int(r.impacts) == int(mid.impacts) and int(r.outcome) == int(mid.outcome)
    fd = (float(getattr(hi, field)) - float(getattr(lo, field))) / (2 * h)
    ad = _derivatives(name.removesuffix("-disp"), x0)[field]
    assert ad == pytest.approx(fd, rel=rel)
    assert abs(fd) > 1e-6  # a derivative that could be wrong


def test_jacfwd_under_vmap_over_blocks():
    sizes = jnp.array([0.4, 0.5, 0.6])

    def f(period, size):
        return jr.simulate(
            jr.Block(3.0, size), jr.LinearIsolator(period, 0.35, 0.5), PULSE
        ).max_rotation

    batched = jax.vmap(jax.jacfwd(f), in_axes=(None, 0))(2.0, sizes)
    one_by_one = np.array([float(jax.jacfwd(f)(2.0, s)) for s in sizes])
    # Batched and one-by-one runs are separate compiles and can differ in the
    # last bits (XLA fuses differently); the adaptive solver turns that into
    # ~1e-9 here, far below the derivative's own error at rtol 1e-8 (~1e-6
    # against central differences at rtol 1e-10).
    np.testing.assert_allclose(np.asarray(batched), one_by_one, rtol=1e-7)
    assert np.all(np.abs(one_by_one) > 0)


def test_tune_isolator_lowers_objective_within_bounds():
    blocks = jr.Block(jnp.array([3.0, 4.0]), jnp.array([0.5, 1.0]))
    motions = jr.MPPulse(
        jnp.array([1.15, 0.87]),
        jnp.array([0.68, 0.33]),
        jnp.array([1.6, 2.3]),
        jnp.array([180.0, 100.0]),
    )
    bounds = {"period": (1.0, 4.0), "damping": (0.05, 0.6)}

    def linear(p):
        return jr.LinearIsolator(p["period"], p["damping"], 0.5)

    res = jr.design.tune_isolator(
        linear,
        {"period": 2.0, "damping": 0.35},
        blocks,
        motions,
        bounds=bounds,
        steps=4,
    )
    # Another optimisation (other function, start, bounds and capacity) of the
    # same isolator type reuses the compile.
    compiles = _design._value_and_grad._cached._cache_size()
    jr.design.tune_isolator(
        lambda p: jr.LinearIsolator(p["period"], p["damping"], 0.5),
        {"period": 3.0, "damping": 0.2},
        blocks,
        motions,
        bounds={"period": (1.5, 3.5), "damping": (0.1, 0.5)},
        capacity=0.25,
        steps=1,
    )
    assert _design._value_and_grad._cached._cache_size() == compiles
    # The gradient (chain rule through `make_base`, outside the compile) matches
    # central differences of the objective (evaluations with steps=0).
    for k, h in (("period", 1e-4), ("damping", 1e-5)):
        side = []
        for sign in (1, -1):
            start = {"period": 2.0, "damping": 0.35}
            start[k] += sign * h
            one = jr.design.tune_isolator(
                linear, start, blocks, motions, bounds=bounds, steps=0
            )
            side.append(one.objective[0])
        difference = (side[0] - side[1]) / (2 * h)
        assert res.gradient[k][0] == pytest.approx(difference, rel=1e-3)
        assert abs(res.gradient[k][0]) > 1e-3  # a gradient that could be wrong
    assert res.objective.shape == (5,)
    assert res.objective.min() < res.objective[0]
    for k, (lo, hi) in bounds.items():
        assert np.all((res.params[k] >= lo) & (res.params[k] <= hi))
    # The history's responses are those of simulate at the same parameters.
    one = jr.simulate(
        jr.Block(4.0, 1.0),
        jr.LinearIsolator(res.params["period"][2], res.params["damping"][2], 0.5),
        jr.MPPulse(0.87, 0.33, 2.3, 100.0),
    )
    assert res.max_rotation[2, 1, 1] == pytest.approx(float(one.max_rotation), rel=1e-9)
    with pytest.raises(ValueError, match="outside bounds"):
        jr.design.tune_isolator(
            lambda p: jr.LinearIsolator(p["period"], 0.3, 0.5),
            {"period": 5.0},
            blocks,
            motions,
            bounds={"period": (1.0, 4.0)},
        )


REF_CASES = [
    # (name, slenderness, size, parameter)
    ("linear-period", 3.0, 0.5, "period"),
    ("linear-damping", 3.0, 0.5, "damping"),
    ("fixed-amplitude", 6.0, 2.0, "amplitude"),
]


@pytest.mark.parametrize(
    "name, lam, size, param", REF_CASES, ids=[c[0] for c in REF_CASES]
)
def test_jacfwd_matches_differences_of_scipy_reference(name, lam, size, param):
    """jaxrock's derivative against central differences of the independent
    reference (DOP853, rtol 1e-12; h = 1e-5 relative; agreement 1e-4 relative,
    the differences' own truncation error being about 1e-6 here)."""
    import reference as ref

    values = {"period": 2.0, "damping": 0.35, "amplitude": 1.15}
    x0 = values[param]

    def reference(x):
        v = dict(values, **{param: x})
        acc, t_end, max_step = ref.mp_pulse(v["amplitude"], 0.68, 1.6, 180.0)
        base = (
            ("fixed",)
            if param == "amplitude"
            else ("linear", v["period"], v["damping"], 0.5)
        )
        return ref.simulate(
            lam, size, base, acc, t_end + 5.0, max_step, rtol=1e-12, atol=1e-14
        )

    h = 1e-5 * x0
    lo, hi = reference(x0 - h), reference(x0 + h)
    assert lo["impacts"] == hi["impacts"] >= 2
    fd = (hi["max_rotation"] - lo["max_rotation"]) / (2 * h)
    # The same functions as above (same block, base and San Fernando pulse).
    ad = _derivatives(name, x0)["max_rotation"]
    assert ad == pytest.approx(fd, rel=1e-4)


def test_a_record_scaled_by_a_traced_factor_differentiates():
    """`Record.scaled` takes a traced factor (under `jacfwd`) as it takes a
    concrete one: its derivative is that of the record built with the
    factor (`Record(samples, dt, factor=x)`)."""
    t = np.arange(0.0, 2.0, 0.01)
    record = jr.Record(4.0 * np.sin(2 * np.pi * t) * np.sin(np.pi * t / 2.0), 0.01)
    block, base = jr.Block(3.0, 0.5), jr.LinearIsolator(2.0, 0.35, 0.5)

    def peak(scaled):
        return lambda x: jr.simulate(block, base, scaled(x)).max_base_displacement

    via_scaled = jax.jacfwd(peak(record.scaled))(1.2)
    via_factor = jax.jacfwd(peak(lambda x: jr.Record(record.samples, 0.01, factor=x)))(
        1.2
    )
    assert float(via_scaled) > 0
    assert float(via_scaled) == pytest.approx(float(via_factor), rel=1e-12)


@pytest.mark.parametrize("eta", [1.0, 1.5])
def test_rates_tangent_at_rest_is_finite(eta):
    """An integrated friction pendulum's |z|^(eta - 1) at rest (z = 0) for
    1 <= eta < 2: its tangent is finite (pow's derivative at 0 is inf, which
    times a zero tangent is NaN, and stopped every forward-mode derivative of
    an analysis from rest)."""
    base = jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=eta)
    state = base.initial_state()
    _, tangent = jax.jvp(
        lambda s: base.rates(s, jnp.asarray(0.0)), (state,), (jnp.ones_like(state),)
    )
    assert np.all(np.isfinite(tangent))
