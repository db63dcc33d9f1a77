"""sin and cos of one argument together, in float64 to 1 ulp, from polynomials.

XLA evaluates a float64 `sin` or `cos` on the CPU with a scalar library call
(~15 ns an element), which made the transcendental functions most of the cost
of a solver step (the pulse and the block's geometry need two sin/cos pairs per
evaluation). `sincos` shares one argument reduction and evaluates two short
polynomials that XLA fuses and vectorizes (~5 ns for both). The reduction is
Cody-Waite's by pi/2 with the constants of fdlibm, exact for |x| < 2^19 pi/2
(~8e5); the polynomials are fdlibm's `__kernel_sin` and `__kernel_cos` on
|r| <= pi/4. Measured: at most 1 ulp from NumPy over |x| < 3000
(tests/test_trig.py). Derivatives are exact (d sin = cos dx, d cos = -sin dx).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

# pi/2 = _PIO2_1 + _PIO2_2 + _PIO2_2T: _PIO2_1 has 33 significant bits, so
# n * _PIO2_1 is exact for |n| < 2^20, and the residue keeps ~100 bits of pi/2.
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_2T = 2.02226624879595063154e-21
_S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C = (
    4.16666666666666019037e-02,
    -1.38888888888741095749e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)
# Largest |x| of the exact reduction (the callers' arguments stay far below it).
LIMIT = 2.0**19 * np.pi / 2


def _horner(z, coefficients):
    out = coefficients[-1]
    for c in coefficients[-2::-1]:
        out = c + z * out
    return out


@jax.custom_jvp
def sincos(x):
    """(sin x, cos x) of a float64 array, for |x| < LIMIT (else inaccurate)."""
    return _sincos(x)


# Traced once per shape and dtype, then inlined from JAX's cache: a map's chunk
# loop calls `sincos` about 40 times, and traces 0.25 s faster (of 1 s) than
# when each call traces the body again.
@functools.partial(jax.jit, inline=True)
def _sincos(x):
    n = jnp.round(x * (2.0 / np.pi))
    r = (x - n * _PIO2_1) - n * _PIO2_2
    tail = n * _PIO2_2T
    y = r - tail  # the reduced argument, |y| <= pi/4, as y + dy
    dy = (r - y) - tail
    z = y * y
    v = z * y
    sin = y - ((z * (0.5 * dy - v * _horner(z, _S[1:])) - dy) - v * _S[0])
    half = 0.5 * z
    w = 1.0 - half
    cos = w + (((1.0 - w) - half) + (z * z * _horner(z, _C) - y * dy))
    # Quadrant q: (sin, cos) x = (s, c), (c, -s), (-s, -c), (-c, s). Elementwise
    # (`jnp.select` is an argmax, a reduction that splits XLA's fusions).
    quadrant = n.astype(jnp.int32)
    odd = (quadrant & 1) == 1
    sin_sign = jnp.where((quadrant & 2) == 2, -1.0, 1.0)
    cos_sign = jnp.where(((quadrant + 1) & 2) == 2, -1.0, 1.0)
    return (
        sin_sign * jnp.where(odd, cos, sin),
        cos_sign * jnp.where(odd, sin, cos),
    )


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    sin, cos = sincos(x)
    return (sin, cos), (cos * dx, -sin * dx)
