"""The rigid block."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._misc import GRAVITY, AbstractChecked, Constraint, parameter


class Block(AbstractChecked):
    """A rectangular rigid block, 2b wide and 2h high (SI units).

    `slenderness` is lambda = h / b (0.01 to 1000) and `size` is
    r = sqrt(b^2 + h^2) (m, 0.001 to 1000), the half-diagonal. Derived:
    alpha = atan(b / h) (rad), b = r sin(alpha), h = r cos(alpha), and the
    frequency parameter p = sqrt(3 g / (4 r)) (rad/s).
    Results do not depend on the block's mass, only on the mass ratio of the base.
    Both fields may carry batch axes (for `vmap`).
    """

    slenderness: Float[Array, "..."] = parameter("slenderness")
    size: Float[Array, "..."] = parameter("size")

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
        return jnp.arctan(1.0 / self.slenderness)

    # sin(alpha) = 1 / sqrt(1 + lambda^2) and cos(alpha) = lambda sin(alpha): a
    # square root instead of arctan, sin and cos in every evaluation.
    @property
    def b(self) -> Float[Array, "..."]:
        return self.size / jnp.sqrt(1.0 + self.slenderness**2)

    @property
    def h(self) -> Float[Array, "..."]:
        return self.slenderness * self.b

    @property
    def p(self) -> Float[Array, "..."]:
        return jnp.sqrt(3.0 * GRAVITY / (4.0 * self.size))

    @property
    def uplift_acceleration(self) -> Float[Array, "..."]:
        """g tan(alpha) = g b / h (m/s^2): the absolute base acceleration to uplift."""
        return GRAVITY / self.slenderness
