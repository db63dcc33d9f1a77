"""Small shared helpers: constants and construction-time checks."""

import jax
import jax.numpy as jnp
import numpy as np

GRAVITY = 9.81  # m/s^2


def as_float(x):
    """Converter for physical parameters: a float64 (when x64 is on) JAX array."""
    return jnp.asarray(x, dtype=float)


def _concrete(x):
    """The value as a NumPy array, or None when it is traced (checks skipped)."""
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def check(name: str, x, ok, allowed: str) -> None:
    """Raise `ValueError` naming `name` and the allowed range unless `ok(x)` holds.

    Skipped for traced values (inside `jit`/`vmap`), where the caller's concrete
    inputs have been checked already.
    """
    value = _concrete(x)
    if value is None:
        return
    if not np.all(np.isfinite(value)) or not np.all(ok(value)):
        bad = value if value.ndim == 0 else value[~(np.isfinite(value) & ok(value))]
        shown = np.ravel(bad)[:3].tolist()
        raise ValueError(
            f"`{name}` must be {allowed}, got {shown[0] if value.ndim == 0 else shown}"
        )


def positive(name: str, x) -> None:
    check(name, x, lambda v: v > 0, "finite and > 0")


def nonnegative(name: str, x) -> None:
    check(name, x, lambda v: v >= 0, "finite and >= 0")


def first_true(conditions, values, default):
    """`jnp.select` as nested `where`s: the value of the first true condition.

    Elementwise, so XLA fuses it with its neighbours (`jnp.select` takes an
    argmax, a reduction that splits fusions: costly in the flat loop of maps).
    """
    out = default
    for condition, value in zip(reversed(conditions), reversed(values)):
        out = jnp.where(condition, value, out)
    return out


def computed_once(tree):
    """`tree` unchanged (bit for bit), computed once: a fusion boundary for XLA.

    XLA:CPU copies cheap elementwise work into every fusion that reads it, so a
    value read by many outputs (an event condition, the step's new state) was
    recomputed for each: in the flat loop of maps, the pulse and the step's
    combination of stages about 20 times an iteration. XLA does not copy a
    division, so each floating leaf x becomes x / sign(1 + |x|): x / 1, exact,
    with a divisor that XLA cannot fold away (a constant one would be).
    """

    def once(x):
        if not jnp.issubdtype(x.dtype, jnp.floating):
            return x
        return x / jnp.sign(1.0 + jnp.abs(x))

    return jax.tree_util.tree_map(once, tree)
