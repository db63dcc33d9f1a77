"""The rigid block."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._misc import GRAVITY, AbstractChecked, Constraint, parameter, real_number


def _optional(name: str, unit: str):
    """A parameter's field that may be None (not given)."""
    return eqx.field(
        converter=lambda x: None if x is None else real_number(name, x),
        metadata={"unit": unit},
    )


class Block(AbstractChecked):
    """A rectangular rigid block, 2b wide and 2h high, rocking about its corners.

    The block is given by its slenderness lambda = h / b and its size
    r = sqrt(b^2 + h^2) (m), the half-diagonal. Derived: the angle
    alpha = atan(b / h) (rad), the half-width b = r sin(alpha) and half-height
    h = r cos(alpha) (m), the frequency parameter p = sqrt(3 g / (4 r)) (rad/s)
    and the uplift acceleration g tan(alpha) (m/s^2), with g = 9.81 m/s^2.
    Results do not depend on the block's mass, only on the mass ratio of an
    isolated base. Every parameter may carry batch axes (for `jax.vmap`).

    At an impact that re-uplifts the block, theta'+ = e theta'-. By default
    e is the momentum model's coefficient e_0 (Eq. 2.13 of the paper: from
    the geometry and, on an isolated base, the mass ratio); measured rebounds
    differ from it (soft interfaces rebound less, stone and concrete more),
    so a calibration sets e = f e_0 (`restitution_factor` f) or e itself
    (`restitution`). Either way the horizontal momentum M u' + m h theta' of
    block and base is conserved through the impact, which sets the base's
    velocity after it, and the rest rule and the closed-form free rocking use
    the e applied (docs/model.md). f e_0 <= 1 depends on the base as well as
    on the block: it is checked where the two meet (`simulate`,
    `behavior_map`; `Status.INVALID_INPUT` for traced values).

    The model assumes that the block never slides on its base. Given the
    coefficient of friction mu of the interface (`friction`), an analysis
    checks it: where the horizontal force that holds the block exceeds
    mu times the normal force (|R_x| > mu R_y: in translation, while rocking,
    or as the impulses of an impact), or the normal force would pull
    (R_y < 0), the block would slide, and the analysis ends with
    `Status.SLIDING` (its numbers those of the model without sliding).

    Parameters built from concrete values are checked at construction. Built
    from traced values (inside `jax.jit`, `jax.vmap` or `jax.jacfwd`) they
    cannot be: `simulate` then reports `Status.INVALID_INPUT` with NaN results.

    Args:
        slenderness: lambda = h / b (-), in [0.01, 1000].
        size: r, the half-diagonal (m), in [0.001, 1000].
        restitution_factor: f > 0, the applied coefficient e = f e_0 at a
            re-uplift; default 1 (the momentum model), and f e_0 <= 1.
        restitution: e itself, in [0, 1], whatever the base (instead of
            `restitution_factor`: give one or the other).
        friction: mu > 0, the coefficient of friction between the block and
            its base (-); default None: no check of sliding.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range),
            or both `restitution_factor` and `restitution`.

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
        >>> jr.Block(4.0, 1.0, restitution_factor=0.0)
        Traceback (most recent call last):
        ...
        ValueError: `restitution_factor` must be finite and > 0, got 0.0
    """

    slenderness: Float[Array, "..."] = parameter("slenderness", "1")
    size: Float[Array, "..."] = parameter("size", "m")
    # One of the two is None: which one decides the impact map's form statically.
    restitution_factor: Float[Array, "..."] | None = _optional(
        "restitution_factor", "1"
    )
    restitution: Float[Array, "..."] | None = _optional("restitution", "1")
    # None: no check of sliding (statically: the slide condition is absent).
    friction: Float[Array, "..."] | None = _optional("friction", "1")

    def __init__(
        self,
        slenderness,
        size,
        restitution_factor=None,
        restitution=None,
        friction=None,
    ):
        if restitution_factor is not None and restitution is not None:
            raise ValueError(
                "give `restitution_factor` (a factor on the momentum model's e) or "
                "`restitution` (e itself), not both"
            )
        self.slenderness = slenderness
        self.size = size
        if restitution is None and restitution_factor is None:
            # 1 for each block: a batch of blocks keeps one batch shape.
            # (NumPy's shape: the fields are converted, and refused, after
            # __init__; a traced value has its shape too.)
            shape = np.broadcast_shapes(np.shape(slenderness), np.shape(size))
            restitution_factor = jnp.ones(shape, dtype=float)
        self.restitution_factor = restitution_factor
        self.restitution = restitution
        self.friction = friction

    def constraints(self):
        # Beyond these bounds b, h or alpha lose their precision in float64 long
        # before the shape stops being physical.
        return (
            [
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
            + (
                [
                    Constraint(
                        "restitution_factor",
                        self.restitution_factor,
                        lambda v: v > 0,
                        "finite and > 0",
                    )
                ]
                if self.restitution is None
                else [
                    Constraint(
                        "restitution",
                        self.restitution,
                        lambda v: (v >= 0) & (v <= 1),
                        "finite, >= 0 and <= 1",
                    )
                ]
            )
            + (
                []
                if self.friction is None
                else [
                    Constraint(
                        "friction", self.friction, lambda v: v > 0, "finite and > 0"
                    )
                ]
            )
        )

    def applied_restitution(self, e0):
        """The coefficient e applied at a re-uplift, given the momentum model's
        e0 (`restitution`): f e0, or the `restitution` given."""
        if self.restitution is not None:
            return self.restitution
        return self.restitution_factor * e0

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
