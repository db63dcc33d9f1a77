"""Small shared helpers: constants, parameters and their allowed ranges."""

import numbers
from collections.abc import Callable
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool

GRAVITY = 9.81  # m/s^2


def as_float(x):
    """Converter for physical parameters: a float64 (when x64 is on) JAX array."""
    return jnp.asarray(x, dtype=float)


def is_real(x) -> bool:
    """Whether `x` is real-valued: ints and floats, scalar or array, concrete
    or traced (not a string, None, a bool or a complex number)."""
    kind = getattr(getattr(x, "dtype", None), "kind", None)
    if kind is None and not isinstance(x, (str, bytes, bool)) and x is not None:
        try:
            kind = np.asarray(x).dtype.kind
        except (TypeError, ValueError):
            kind = None
    return kind in ("f", "i", "u")


def real_number(name: str, x):
    """`x` as a float array if it is real-valued (`is_real`); else
    `ValueError` naming `name`. Strings, None, booleans and complex numbers
    are refused, not coerced."""
    if not is_real(x):
        raise ValueError(
            f"`{name}` must be a real number (float or int), got {x!r} "
            f"({type(x).__name__})"
        )
    return as_float(x)


def flag(name: str, x) -> bool:
    """`x` if it is True or False; else `ValueError` naming `name` (a
    string such as "no" would count as true)."""
    if not isinstance(x, (bool, np.bool_)):
        raise ValueError(f"`{name}` must be True or False, got {x!r}")
    return bool(x)


def one_real_number(name: str, x, allowed: str):
    """`x` as a 0-d float array if it is one real number (concrete or traced);
    else `ValueError` naming `name` and its range, `allowed`."""
    x = real_number(name, x)
    if x.ndim:
        raise ValueError(
            f"`{name}` must be one number, {allowed}, got an array of shape "
            f"{tuple(x.shape)}"
        )
    return x


def is_count(x) -> bool:
    """A Python or NumPy integer (not a bool): a size, a count, a limit."""
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


def grid_axis(name: str, values) -> np.ndarray:
    """A sweep's axis as a non-empty 1-D float array (`ValueError` naming it)."""
    try:
        x = np.atleast_1d(np.asarray(values))
    except (TypeError, ValueError):
        x = np.asarray([values], dtype=object)
    if x.dtype.kind not in "fiu":
        raise ValueError(f"`{name}` must be an array of real numbers, got {values!r}")
    if x.ndim != 1 or x.size == 0:
        raise ValueError(
            f"`{name}` must be a non-empty 1-D array, got shape {np.shape(values)}"
        )
    return x.astype(float)


def parameter(name: str, unit: str | None = None, **kwargs):
    """A physical parameter's field: a float array leaf, refused (naming it)
    unless real-valued. `unit` (SI, "1" if dimensionless) marks the parameters
    that label results (the coordinates of `to_xarray`); `kwargs` go to
    `equinox.field` (e.g. `default=`).

    Examples:
        >>> import jax.numpy as jnp, jaxrock as jr
        >>> class Spring(jr.AbstractIsolator):  # (abstract: a field's example)
        ...     period: jnp.ndarray = jr.parameter("period", "s")
    """
    metadata = {} if unit is None else {"unit": unit}
    return eqx.field(
        converter=lambda x: real_number(name, x), metadata=metadata, **kwargs
    )


class Constraint(NamedTuple):
    """A parameter's allowed range: `ok` is elementwise on NumPy or JAX arrays,
    `allowed` says the range in words ("finite and > 0"). A module's
    `constraints()` lists them: a concrete value out of range is a
    `ValueError` naming `name` and `allowed`, a traced one an invalid input.

    Examples:
        >>> import jaxrock as jr
        >>> c = jr.Constraint("period", 2.0, lambda v: v > 0, "finite and > 0")
        >>> bool(c.ok(c.value))
        True
    """

    name: str
    value: Any
    ok: Callable
    allowed: str


def finite(name, value) -> Constraint:
    return Constraint(name, value, lambda v: v == v, "finite")


def greater_than_zero(name, value) -> Constraint:
    return Constraint(name, value, lambda v: v > 0, "finite and > 0")


def at_least_zero(name, value) -> Constraint:
    return Constraint(name, value, lambda v: v >= 0, "finite and >= 0")


def in_range(name, value, low, high, unit: str | None = None) -> Constraint:
    """low <= value <= high: "finite, >= low and <= high (unit)"."""
    unit = f" ({unit})" if unit else ""
    return Constraint(
        name,
        value,
        lambda v: (v >= low) & (v <= high),
        f"finite, >= {low:g} and <= {high:g}{unit}",
    )


def broadcast_batch_shape(module) -> tuple[int, ...]:
    """The batch shape of a module's parameters, broadcast together."""
    leaves = [np.shape(x) for x in jax.tree_util.tree_leaves(module)]
    try:
        return tuple(np.broadcast_shapes(*leaves)) if leaves else ()
    except ValueError:
        raise ValueError(
            f"the parameters of {type(module).__name__} must share one batch shape, "
            f"got shapes {leaves}"
        ) from None


def unbatched(name: str, module, result: str) -> None:
    """`ValueError` naming `name` if the module's parameters carry batch axes
    (an analysis that gives one `result` per module)."""
    shape = broadcast_batch_shape(module)
    if shape:
        raise ValueError(
            f"`{name}` must be one {name} (parameters without batch axes), got a "
            f"batch of shape {shape}: one {result} per {name}"
        )


def one_block_options(map_options: dict, result: str) -> None:
    """`ValueError` naming the option if `map_options` give the blocks'
    `restitution_factor` or `restitution` as more than one value: a `result`
    analyses one block, and an array of values would add an axis of blocks
    to its map."""
    for name in ("restitution_factor", "restitution"):
        value = map_options.get(name)
        if value is not None and np.size(value) != 1:
            raise ValueError(
                f"`{name}` must be one number for {result} (the analyses of one "
                f"block), got shape {np.shape(value)}"
            )


def scale_factors(factor, name: str = "factor") -> np.ndarray:
    """Scale factors as an array of real numbers, each finite and > 0
    (`ValueError` naming `name` else: a string, a bool or None is refused,
    not converted). Traced factors (under `jax.jacfwd`) are returned as they
    are, unchecked (`AbstractChecked.valid` covers them)."""
    if not is_real(factor):
        raise ValueError(f"`{name}` must be finite and > 0, got {factor!r}")
    if isinstance(factor, jax.core.Tracer):
        return jnp.asarray(factor, dtype=float)
    factor = np.asarray(factor, dtype=float)
    if factor.size == 0 or not np.all(np.isfinite(factor) & (factor > 0)):
        raise ValueError(f"`{name}` must be finite and > 0, got {factor.tolist()}")
    return factor


def describe_values(x) -> str:
    """A parameter for a title: its value, or the range of a batch."""
    x = np.asarray(x)
    if x.size == 1:
        return f"{float(x.reshape(-1)[0]):g}"
    return f"{x.min():g}..{x.max():g} ({x.size} values)"


class AbstractChecked(eqx.Module):
    """A module whose parameters have allowed ranges (`constraints`).

    Concrete values are checked when the module is built (`ValueError` naming
    the parameter and the range). Traced values (a module built inside `jit`,
    `vmap` or `jacfwd`) cannot be: the engines then test `valid()` and report
    `Status.INVALID_INPUT` with NaN results.
    """

    def constraints(self) -> list[Constraint]:
        return []

    def describe(self) -> str:
        """A short description with the parameters' values (for titles)."""
        return type(self).__name__

    def __check_init__(self):
        for c in self.constraints():
            nonempty(c.name, c.value)
            check(c.name, c.value, c.ok, c.allowed)

    def valid(self) -> Bool[Array, ""]:
        """Every parameter finite and in its range (traceable)."""
        out = jnp.asarray(True)
        for c in self.constraints():
            v = jnp.asarray(c.value)
            out = out & jnp.all(jnp.isfinite(v) & c.ok(v))
        return out


def _concrete(x):
    """The value as a NumPy array, or None when it is traced (checks skipped)."""
    if isinstance(x, jax.core.Tracer):
        return None
    return np.asarray(x)


def nonempty(name: str, x) -> None:
    """Raise `ValueError` naming `name` if `x` is an empty array: a batch of
    no parameters, which would make an analysis of nothing."""
    if np.size(_concrete(x)) == 0:
        raise ValueError(f"`{name}` must hold at least one value, got an empty array")


def check(name: str, x, ok, allowed: str) -> None:
    """Raise `ValueError` naming `name` and the allowed range unless `ok(x)` holds.

    Skipped for traced values (inside `jit`/`vmap`: `AbstractChecked.valid`
    covers those). `ok` may read other parameters (of a broadcast shape).
    """
    value = _concrete(x)
    if value is None:
        return
    if not is_real(value):  # a bool, a string, None: not a number to compare
        raise ValueError(f"`{name}` must be {allowed}, got {x!r}")
    try:
        good = np.asarray(ok(value))
    except jax.errors.TracerArrayConversionError:  # `ok` reads a traced parameter
        return
    good = good & np.isfinite(value)
    if not np.all(good):
        value = np.broadcast_to(value, good.shape)
        bad = value if value.ndim == 0 else value[~good]
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


def counted(n: int, one: str, many: str) -> str:
    """n and the noun for it: "1 analysis", "4 analyses"."""
    return f"{n} {one if n == 1 else many}"


def turned_off(setting: str) -> bool:
    """Whether an environment variable's value turns a feature off: "off",
    "0", "none", "false" or "no", in any case."""
    return setting.strip().lower() in {"off", "0", "none", "false", "no"}


def is_none(x) -> bool:
    """None: a leaf to `eqx.tree_at` or `tree_map` (`is_leaf`), not an empty node."""
    return x is None


def where_lanes(mask, new, old):
    """Per lane (leading axis): `new` where `mask`, else `old` (pytrees)."""
    return jax.tree_util.tree_map(
        lambda n, o: jnp.where(mask.reshape((-1,) + (1,) * (o.ndim - 1)), n, o),
        new,
        old,
    )


def range_maxima(level, pad=0.0):
    """The table of maxima of `level` (last axis n) over every range of 2^l
    values, l = 0, 1, ..., L - 1 (2^(L-1) >= n): axis -2. Ranges past the end
    read `pad`."""
    n = level.shape[-1]
    table = [level]
    width = 1
    while width < n:
        tail = jnp.full(level.shape[:-1] + (width,), pad, level.dtype)
        shifted = jnp.concatenate([level[..., width:], tail], axis=-1)
        level = jnp.maximum(level, shifted)
        table.append(level)
        width *= 2
    return jnp.stack(table, axis=-2)
