"""The polynomial sincos against NumPy's sin and cos (float64)."""

import jax
import numpy as np
import pytest

from jaxrock._trig import LIMIT, sincos


@pytest.mark.parametrize("scale", [1e-300, 1e-8, 1.0, 4.0, 100.0, 3000.0, LIMIT])
def test_sincos_within_one_ulp_of_numpy(scale):
    x = np.random.default_rng(0).uniform(-scale, scale, 200_000)
    x = np.concatenate([x, np.arange(-64, 65) * (np.pi / 4)])  # quadrant edges
    sin, cos = map(np.asarray, jax.jit(sincos)(x))
    # 1 ulp of the result, but at least 1 ulp of 1 near zeros (as fdlibm's bound)
    for got, want in ((sin, np.sin(x)), (cos, np.cos(x))):
        ulp = np.spacing(np.maximum(np.abs(want), 0.0 if scale < 1 else 1.0))
        assert np.max(np.abs(got - want) / ulp) <= 1.0


def test_sincos_derivatives_are_cos_and_minus_sin():
    x = np.linspace(-20.0, 20.0, 1001)
    ds, dc = jax.vmap(jax.jacfwd(sincos))(x)
    np.testing.assert_array_equal(np.asarray(ds), np.asarray(sincos(x)[1]))
    np.testing.assert_array_equal(np.asarray(dc), -np.asarray(sincos(x)[0]))
