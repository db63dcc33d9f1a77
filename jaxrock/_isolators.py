"""The support of the block: a fixed base or an isolated base (the isolator).

An isolated base of mass m_b carries the block of mass m; `mass_ratio` is
mbar = m / m_b and M = m + m_b. The base state is u (m, relative to the ground),
u' (m/s) and, for hysteretic isolators only, the Bouc-Wen variable z (-).
Forces are returned per unit total mass, f = F / M (m/s^2), so the block mass
never appears.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._misc import GRAVITY, as_float, check, nonnegative, positive


class AbstractIsolator(eqx.Module):
    """What lies between the ground and the block.

    `n_states` is the size of the base state (0: no base degree of freedom).
    `free_rocking_closed_form`: once the ground is still, a rocking block's
    motion has a closed form (maps then finish it without steps, `_free.py`).
    """

    n_states: ClassVar[int]
    free_rocking_closed_form: ClassVar[bool] = False

    @abc.abstractmethod
    def initial_state(self) -> Float[Array, " n"] | None:
        """The base state at rest."""

    @abc.abstractmethod
    def force(self, state: Float[Array, " n"]) -> Float[Array, ""]:
        """Isolator force per unit total mass, F / M (m/s^2)."""

    @abc.abstractmethod
    def rates(self, state: Float[Array, " n"], u_ddot: Float[Array, ""]):
        """Time derivative of the base state given the base acceleration u''."""

    @property
    @abc.abstractmethod
    def block_mass_fraction(self) -> Float[Array, ""]:
        """m / M = mbar / (1 + mbar); zero for a fixed base (m_b -> infinity)."""

    @abc.abstractmethod
    def free_vibration_bounds(self, state):
        """Bounds (on |u| in m, on |F / M| in m/s^2) for all later times.

        Valid while the ground is still and the block moves with the base: the
        base's energy E cannot grow then, and bounds both. Used to end an
        analysis early (nothing can happen any more); +inf where no bound holds.
        """


class FixedBase(AbstractIsolator):
    """No isolation: the block stands on the ground (Housner's problem, 1 DOF)."""

    n_states: ClassVar[int] = 0
    free_rocking_closed_form: ClassVar[bool] = True  # Housner's inverted pendulum

    def initial_state(self):
        return None

    def force(self, state):
        raise NotImplementedError("a fixed base has no isolator force")

    def rates(self, state, u_ddot):
        return None

    def free_vibration_bounds(self, state):
        return 0.0, 0.0

    @property
    def block_mass_fraction(self):
        return jnp.asarray(0.0)


class LinearIsolator(AbstractIsolator):
    """Linear viscoelastic isolator, F = k u + c u' (SI).

    k = M (2 pi / T_s)^2 and c = 2 xi M (2 pi / T_s): `period` T_s (s) > 0,
    `damping` xi >= 0 (fraction of critical), `mass_ratio` m / m_b > 0.
    The paper's values are T_s = 2 s, xi = 0.35, mass ratio 0.5.
    """

    period: Float[Array, "..."] = eqx.field(converter=as_float)
    damping: Float[Array, "..."] = eqx.field(converter=as_float)
    mass_ratio: Float[Array, "..."] = eqx.field(converter=as_float)
    n_states: ClassVar[int] = 2

    def __check_init__(self):
        positive("period", self.period)
        nonnegative("damping", self.damping)
        positive("mass_ratio", self.mass_ratio)

    def initial_state(self):
        return jnp.zeros(2, dtype=self.period.dtype)

    def force(self, state):
        omega = 2.0 * jnp.pi / self.period
        return omega**2 * state[0] + 2.0 * self.damping * omega * state[1]

    def rates(self, state, u_ddot):
        return jnp.stack([state[1], u_ddot])

    def free_vibration_bounds(self, state):
        # E = u'^2 / 2 + omega^2 u^2 / 2 decays (E' = -2 xi omega u'^2), and
        # |u| <= sqrt(2E) / omega, |F / M| <= omega sqrt(2E) sqrt(1 + 4 xi^2).
        omega = 2.0 * jnp.pi / self.period
        # (sqrt of at least 1e-300: a finite derivative at rest)
        amplitude = jnp.sqrt(
            jnp.maximum(state[1] ** 2 + (omega * state[0]) ** 2, 1e-300)
        )
        return amplitude / omega, omega * amplitude * jnp.sqrt(
            1.0 + 4.0 * self.damping**2
        )

    @property
    def block_mass_fraction(self):
        return self.mass_ratio / (1.0 + self.mass_ratio)


class FrictionPendulum(AbstractIsolator):
    """Friction pendulum system with Bouc-Wen hysteresis, F = K u + Q z (SI).

    K = M g / R and Q = mu M g, with `friction` mu >= 0, `radius` R (m) > 0 and
    Y z' = A u' - gamma |u'| z |z|^(eta - 1) - beta u' |z|^eta,
    `yield_displacement` Y (m) > 0. The paper uses mu = 0.11, R = 2.24 m and
    A = 1, gamma = 0.9, beta = 0.1, eta = 2, Y = 0.5 mm. z is stiff: |z'| reaches
    |u'| / Y.
    """

    friction: Float[Array, "..."] = eqx.field(converter=as_float)
    radius: Float[Array, "..."] = eqx.field(converter=as_float)
    mass_ratio: Float[Array, "..."] = eqx.field(converter=as_float)
    yield_displacement: Float[Array, "..."] = eqx.field(
        default=5e-4, converter=as_float
    )
    A: Float[Array, "..."] = eqx.field(default=1.0, converter=as_float)
    gamma: Float[Array, "..."] = eqx.field(default=0.9, converter=as_float)
    beta: Float[Array, "..."] = eqx.field(default=0.1, converter=as_float)
    eta: Float[Array, "..."] = eqx.field(default=2.0, converter=as_float)
    n_states: ClassVar[int] = 3

    def __check_init__(self):
        nonnegative("friction", self.friction)
        positive("radius", self.radius)
        positive("mass_ratio", self.mass_ratio)
        positive("yield_displacement", self.yield_displacement)
        positive("A", self.A)
        check("eta", self.eta, lambda v: v >= 1, "finite and >= 1")
        check("gamma", self.gamma, lambda v: v == v, "finite")
        check("beta", self.gamma + self.beta, lambda v: v > 0, "with gamma + beta > 0")

    def initial_state(self):
        return jnp.zeros(3, dtype=self.radius.dtype)

    def force(self, state):
        return GRAVITY * (state[0] / self.radius + self.friction * state[2])

    def free_vibration_bounds(self, state):
        # E = u'^2 / 2 + g u^2 / (2R) + mu g Y z^2 / (2A) cannot grow when
        # gamma >= |beta| (Bouc-Wen is then dissipative); |u| <= sqrt(2 R E / g),
        # |z| <= sqrt(2 A E / (mu g Y)) and |F / M| <= g |u| / R + mu g |z|.
        u, u_dot, z = state[0], state[1], state[2]
        mu_g = self.friction * GRAVITY
        energy = (
            0.5 * u_dot**2
            + 0.5 * GRAVITY * u**2 / self.radius
            + 0.5 * mu_g * self.yield_displacement * z**2 / self.A
        )
        energy = jnp.maximum(energy, 1e-300)  # a finite derivative of sqrt at rest
        u_bound = jnp.sqrt(2.0 * self.radius * energy / GRAVITY)
        # Starting from z = 0, |z| never exceeds z_max = (A / (gamma + beta))^(1/eta).
        z_max = (self.A / (self.gamma + self.beta)) ** (1.0 / self.eta)
        z_bound = jnp.minimum(
            z_max,
            jnp.sqrt(
                2.0
                * self.A
                * energy
                / jnp.maximum(mu_g * self.yield_displacement, 1e-300)
            ),
        )
        f_bound = GRAVITY * u_bound / self.radius + mu_g * z_bound
        dissipative = self.gamma >= jnp.abs(self.beta)
        return (
            jnp.where(dissipative, u_bound, jnp.inf),
            jnp.where(dissipative, f_bound, jnp.inf),
        )

    def rates(self, state, u_ddot):
        u_dot, z = state[1], state[2]
        abs_z = jnp.abs(z)
        power = abs_z ** (self.eta - 1.0)  # |z|^eta = |z| power: one pow, not two
        z_dot = (
            self.A * u_dot
            - self.gamma * jnp.abs(u_dot) * z * power
            - self.beta * u_dot * abs_z * power
        ) / self.yield_displacement
        return jnp.stack([u_dot, u_ddot, z_dot])

    @property
    def block_mass_fraction(self):
        return self.mass_ratio / (1.0 + self.mass_ratio)
