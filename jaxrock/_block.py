"""The rigid block."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._misc import GRAVITY, AbstractChecked, Constraint, parameter


class Block(AbstractChecked):
    """A rectangular rigid block, 2b wide and 2h high, rocking about its corners.

    The block is given by its slenderness lambda = h / b and its size
    r = sqrt(b^2 + h^2) (m), the half-diagonal. Derived: the angle
    alpha = atan(b / h) (rad), the half-width b = r sin(alpha) and half-height
    h = r cos(alpha) (m), the frequency parameter p = sqrt(3 g / (4 r)) (rad/s)
    and the uplift acceleration g tan(alpha) (m/s^2), with g = 9.81 m/s^2.
    Results do not depend on the block's mass, only on the mass ratio of an
    isolated base. Both fields may carry batch axes (for `jax.vmap`).

    Parameters built from concrete values are checked at construction. Built
    from traced values (inside `jax.jit`, `jax.vmap` or `jax.jacfwd`) they
    cannot be: `simulate` then reports `Status.INVALID_INPUT` with NaN results.

    Args:
        slenderness: lambda = h / b (-), in [0.01, 1000].
        size: r, the half-diagonal (m), in [0.001, 1000].

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> block = jr.Block(slenderness=4.0, size=1.0)
        >>> round(float(block.alpha), 4), round(float(block.p), 4)
        (0.245, 2.7125)
        >>> round(float(block.b), 4), round(float(block.uplift_acceleration), 4)
        (0.2425, 2.4525)
        >>> jr.Block(4.0, 0.0)
        Traceback (most recent call last):
        ...
        ValueError: `size` must be finite, >= 0.001 and <= 1000 (m), got 0.0
    """

    slenderness: Float[Array, "..."] = parameter("slenderness", "1")
    size: Float[Array, "..."] = parameter("size", "m")

    def constraints(self):
        # Beyond these bounds b, h or alpha lose their precision in float64 long
        # before the shape stops being physical.
        return [
            Constraint(
                "slenderness",
                self.slenderness,
                lambda v: (v >= 0.01) & (v <= 1000),
                "finite, >= 0.01 and <= 1000",
            ),
            Constraint(
                "size",
                self.size,
                lambda v: (v >= 1e-3) & (v <= 1000),
                "finite, >= 0.001 and <= 1000 (m)",
            ),
        ]

    @property
    def alpha(self) -> Float[Array, "..."]:
        """alpha = atan(b / h) (rad): the angle of the diagonal to the vertical."""
        return jnp.arctan(1.0 / self.slenderness)

    # sin(alpha) = 1 / sqrt(1 + lambda^2) and cos(alpha) = lambda sin(alpha): a
    # square root instead of arctan, sin and cos in every evaluation.
    @property
    def b(self) -> Float[Array, "..."]:
        """b = r sin(alpha) (m): the half-width."""
        return self.size / jnp.sqrt(1.0 + self.slenderness**2)

    @property
    def h(self) -> Float[Array, "..."]:
        """h = r cos(alpha) (m): the half-height."""
        return self.slenderness * self.b

    @property
    def p(self) -> Float[Array, "..."]:
        """p = sqrt(3 g / (4 r)) (rad/s): the frequency parameter."""
        return jnp.sqrt(3.0 * GRAVITY / (4.0 * self.size))

    @property
    def uplift_acceleration(self) -> Float[Array, "..."]:
        """g tan(alpha) = g b / h (m/s^2): the absolute base acceleration to uplift."""
        return GRAVITY / self.slenderness
