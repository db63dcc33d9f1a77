"""The support of the block: a fixed base or an isolated base (the isolator).

An isolated base of mass m_b carries the block of mass m; `mass_ratio` is
mbar = m / m_b and M = m + m_b. The base state is u (m, relative to the ground),
u' (m/s) and, for a Bouc-Wen isolator (a friction pendulum, a bilinear
isolator), the Bouc-Wen variable z (-) or, with z in closed form, what z
depends on (`AbstractClosedFormBoucWen`).
Forces are returned per unit total mass, f = F / M (m/s^2), so the block mass
never appears.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._misc import (
    GRAVITY,
    AbstractChecked,
    Constraint,
    at_least_zero,
    broadcast_batch_shape,
    check,
    computed_once,
    describe_values,
    greater_than_zero,
    is_count,
    nonempty,
    one_real_number,
    parameter,
    real_number,
)
from ._translation import free_vibration, free_vibration_bounds, translation_tables
from ._trig import sincos

# The largest mass ratio m / m_b: a base a million times lighter than its
# block (beyond any isolator; the momentum of an impact loses its digits).
MAX_MASS_RATIO = 1e6


def mass_ratio_constraint(value) -> Constraint:
    """`mass_ratio` (m / m_b) in (0, `MAX_MASS_RATIO`]."""
    return Constraint(
        "mass_ratio",
        value,
        lambda v: (v > 0) & (v <= MAX_MASS_RATIO),
        f"finite, > 0 and <= {MAX_MASS_RATIO:g}",
    )


def _static_eta(x) -> float:
    """`IntegratedFrictionPendulum.eta` as a Python float (static: each value
    compiles once), else `ValueError` naming it: not a string, a bool, an
    array of several values or a traced value."""
    if isinstance(x, jax.core.Tracer):
        raise ValueError(
            "`eta` is static (each value compiles once): give one Python "
            "number, not a traced value"
        )
    return float(one_real_number("eta", x, "finite and >= 1"))


class Stop(AbstractChecked):
    """A stop at an isolator's `capacity`: a bumper, a moat wall's padding,
    the rim of a dish, which the base compresses past |u| = capacity.

    A spring and a dashpot in parallel, per unit total mass: past the gap,
    d = |u| - capacity > 0, the stop pushes the base back with
    F_s / M = w^2 d + 2 zeta w d' (m/s^2, w = 2 pi / `period`), and never
    pulls (F_s >= 0: the base leaves the stop where the push ends). A stiff
    bumper has a short `period`: a contact lasts about `period` / 2. Its
    `damping` zeta sets the energy it takes: the base leaves it with about
    exp(-pi zeta / sqrt(1 - zeta^2)) of its speed (0.53 at zeta = 0.2; a
    little more, since the stop does not pull). The block feels the stop as
    the base's acceleration, a finite shock that the equations, the uplift
    conditions and the events read like any other; an instantaneous impact
    with a coefficient of restitution would instead need a rule of its own
    for the impulse it gives a block at rest or rocking.

    Args:
        period: the stop's contact period 2 pi sqrt(M / k_s) (s), > 0.
        damping: its damping ratio zeta (-), in [0, 1); default 0.2.

    Examples:
        >>> import jaxrock as jr
        >>> stop = jr.Stop(period=0.05, damping=0.2)
        >>> base = jr.LinearIsolator(2.0, 0.35, 0.5, capacity=0.2, stop=stop)
        >>> float(base.capacity), float(base.stop.period)
        (0.2, 0.05)
    """

    period: Float[Array, "..."] = parameter("period", "s")
    damping: Float[Array, "..."] = parameter("damping", "1", default=0.2)

    def constraints(self):
        # Named as the stop's, apart from an isolator's own period and damping.
        return [
            greater_than_zero("Stop.period", self.period),
            Constraint(
                "Stop.damping",
                self.damping,
                lambda v: (v >= 0) & (v < 1),
                "finite, >= 0 and < 1",
            ),
        ]

    def force(self, state, capacity, against=None):
        """F_s / M (m/s^2, signed as u: it pushes the base back) at the base
        state (u, u', ...): against the stop (`against`; None: where it
        pushes, `margin` > 0), the spring's and the dashpot's push, at
        least 0."""
        u, u_dot = state[0], state[1]
        s = jnp.sign(u)
        d = jnp.abs(u) - capacity
        w = 2.0 * jnp.pi / self.period
        push = w * w * d + 2.0 * self.damping * w * s * u_dot
        against = d > 0 if against is None else against
        return jnp.where(against, s * jnp.maximum(push, 0.0), 0.0)

    def margin(self, state, capacity):
        """min(d, push / w^2) = d + min(0, 2 zeta d' / w) (m), with
        d = |u| - capacity and push = w^2 d + 2 zeta w d': > 0 where the stop
        pushes the base. Its force has a kink wherever this crosses 0: where
        the base meets the gap (d = 0, d' > 0, the dashpot's force jumps),
        and where the push ends while the base is still past the gap (a
        damped stop does not pull) or starts again."""
        u, u_dot = state[0], state[1]
        w = 2.0 * jnp.pi / self.period
        lead = 2.0 * self.damping / w * jnp.sign(u) * u_dot
        return jnp.abs(u) - capacity + jnp.minimum(lead, 0.0)


class AbstractIsolator(AbstractChecked):
    """The support of the block: what lies between the ground and the block.

    An isolated base of mass m_b carries the block of mass m, M = m + m_b. The
    isolator's force F on the base is returned per unit total mass,
    f = F / M (m/s^2), so the block's mass never appears. The base state holds
    the displacement u (m, relative to the ground), the velocity u' (m/s) and
    whatever the isolator's hysteresis needs; `n_states` is its size (0: no
    base degree of freedom). `free_rocking_closed_form` marks a base on which
    a rocking block's motion has a closed form once the ground is still
    (`behavior_map` then finishes it without steps). The bases are
    `FixedBase`, `LinearIsolator`, `FrictionPendulum`,
    `IntegratedFrictionPendulum`, `BilinearIsolator`,
    `SphericalRollingIsolator` and `ConicalRollingIsolator`.

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.LinearIsolator(period=2.0, damping=0.35, mass_ratio=0.5)
        >>> isinstance(base, jr.AbstractIsolator), base.n_states
        (True, 2)
    """

    # The displacement |u| the isolator allows (m; its gap to a stop), or
    # None: no limit. Keyword-only, so that every isolator takes it.
    capacity: Float[Array, "..."] | None = eqx.field(
        default=None,
        kw_only=True,
        converter=lambda x: None if x is None else real_number("capacity", x),
    )
    # A stop at the capacity (`Stop`), or None: the base passes it freely
    # (and an analysis that reaches it is `Status.CAPACITY_EXCEEDED`).
    stop: "Stop | None" = eqx.field(default=None, kw_only=True)
    n_states: ClassVar[int]
    # The leading base states that change along a step (the others, whose
    # `rates` are zero, change only at transitions): None, all of them.
    n_integrated: ClassVar[int | None] = None
    free_rocking_closed_form: ClassVar[bool] = False
    # The base state holds a hysteretic variable z (`hysteretic`).
    hysteretic_state: ClassVar[bool] = False
    # The force is proportional to the normal force M g (a pendulum's or a
    # rolling isolator's restoring force and friction), and follows g_eff
    # under vertical ground motion; a rubber or lead bearing's does not.
    weight_borne: ClassVar[bool] = False

    def __check_init__(self):
        if self.capacity is not None:
            nonempty("capacity", self.capacity)
            check("capacity", self.capacity, lambda v: v > 0, "finite and > 0 (m)")
        if self.stop is not None:
            if not isinstance(self.stop, Stop):
                raise ValueError(
                    f"`stop` must be a Stop, got {type(self.stop).__name__}"
                )
            if self.capacity is None:
                raise ValueError(
                    "`stop` needs a `capacity`: the displacement (m) at which "
                    "the base meets it"
                )

    def valid(self):
        out = super().valid()
        if self.stop is not None:
            out = out & self.stop.valid()
        if self.capacity is None:
            return out
        c = jnp.asarray(self.capacity)
        return out & jnp.all(jnp.isfinite(c) & (c > 0))

    @abc.abstractmethod
    def initial_state(self) -> Float[Array, " n"] | None:
        """The base state at rest."""

    @property
    def geometric_limit(self) -> Float[Array, "..."] | None:
        """The largest |u| (m) the isolator's geometry allows, past which its
        model describes nothing real (None, the default: no such bound).
        An analysis whose max |u| reaches it ends CAPACITY_EXCEEDED, as at a
        `capacity`."""
        return None

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

    def at_transition(self, state, turned):
        """The base state after an event (`turned`: the event is a reversal of
        u', see `peak_condition`). The default: unchanged."""
        del turned
        return state

    def turns_back(self, state):
        """Whether `at_transition(state, turned=False)` changes the state (u'
        turned back within a step, unlocated). The default: never."""
        del state
        return jnp.asarray(False)

    def peak_condition(self):
        """The event condition that locates peaks of |u| (None: `condition_base`,
        a new maximum of |u|)."""
        return None

    def translation_tables(self, samples, dt, length):
        """The base's response in translation (the block at rest on it) to a
        record or suite (`Record.unscaled`, `dt`, `length`), tabulated for
        resting lanes of a map to skip samples (`_translation.py`); None
        (the default): the base's state must be integrated."""
        del samples, dt, length
        return None

    def free_vibration(self, state, tau):
        """The base state after tau (s) of free vibration in translation (the
        ground still), where `translation_tables` gives tables."""
        raise NotImplementedError

    @abc.abstractmethod
    def free_vibration_bounds(self, state):
        """Bounds (on |u| in m, on |F / M| in m/s^2) for all later times.

        Valid while the ground is still and the block moves with the base: the
        base's energy E cannot grow then, and bounds both. Used to end an
        analysis early (nothing can happen any more); +inf where no bound holds.
        """


def check_declared_shapes(base: AbstractIsolator) -> None:
    """`ValueError` naming the member of an isolator defined outside jaxrock
    (a user's own) that disagrees with its `n_states`: `initial_state()` and
    `rates(state, u_ddot)` of shape (n_states,) and one dtype, `force(state)`
    and `block_mass_fraction` scalars (for one isolator of a batch). Traced
    abstractly (`jax.eval_shape`): nothing runs. Such a mismatch would
    otherwise broadcast silently or fail deep inside the engine."""
    if isinstance(base, FixedBase) or type(base).__module__.startswith("jaxrock."):
        return
    name = type(base).__name__
    n = getattr(base, "n_states", None)
    if not is_count(n) or n < 2:
        raise ValueError(
            f"`{name}.n_states` must be an int >= 2 (the state holds u, u' and "
            f"what the hysteresis needs), got {n!r}"
        )
    n = int(n)
    shape = broadcast_batch_shape(base)

    def one(x):  # the batch's first isolator
        return jnp.reshape(jnp.broadcast_to(x, shape), (-1,))[0] if shape else x

    def members(b):
        b = jax.tree_util.tree_map(one, b)
        state = b.initial_state()
        if state is None:
            return None
        state = jnp.asarray(state)
        if state.shape != (n,):
            return state, None, None, None
        u_ddot = jnp.zeros((), dtype=jnp.result_type(float))
        force = jnp.asarray(b.force(state))
        rates = jnp.asarray(b.rates(state, u_ddot))
        return state, force, rates, jnp.asarray(b.block_mass_fraction)

    out = jax.eval_shape(members, base)
    if out is None:
        raise ValueError(f"`{name}.initial_state()` must be an array, got None")
    state, force, rates, fraction = out
    expected = f"shape ({n},) (`n_states` = {n})"
    if state.shape != (n,):
        raise ValueError(
            f"`{name}.initial_state()` must be of {expected}, got {state.shape}"
        )
    if force.shape != ():
        raise ValueError(f"`{name}.force(state)` must be a scalar, got {force.shape}")
    if rates.shape != (n,):
        raise ValueError(
            f"`{name}.rates(state, u_ddot)` must be of {expected}, got {rates.shape}"
        )
    if rates.dtype != state.dtype:
        raise ValueError(
            f"`{name}.rates(state, u_ddot)` is {rates.dtype} where "
            f"`initial_state()` is {state.dtype}: give the state the dtype of "
            "the isolator's parameters"
        )
    if fraction.shape != ():
        raise ValueError(
            f"`{name}.block_mass_fraction` must be a scalar, got {fraction.shape}"
        )
    check(  # (skipped where it is traced)
        f"{name}.block_mass_fraction",
        base.block_mass_fraction,
        lambda m: (m > 0) & (m < 1),
        "in (0, 1): m / M, the block's mass over the total mass",
    )


def describe_base(base: AbstractIsolator) -> str:
    """The base's `describe()`, with its capacity and stop (for titles)."""
    text = base.describe()
    if base.capacity is None:
        return text
    text += f", capacity {describe_values(base.capacity)} m"
    if base.stop is not None:
        text += (
            f", stop (T = {describe_values(base.stop.period)} s, "
            f"zeta = {describe_values(base.stop.damping)})"
        )
    return text


class FixedBase(AbstractIsolator):
    """No isolation: the block stands on the ground (Housner's problem, 1 DOF).

    The base has no state (`n_states` = 0) and no force, u = 0 at all times:
    the block rocks under the ground acceleration x_g'' (m/s^2) alone. It is
    the limit m_b -> infinity of an isolated base. Once the ground is still,
    free rocking has a closed form, which `behavior_map` uses to finish an
    analysis without steps.

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.FixedBase()
        >>> base.describe(), base.n_states
        ('fixed base', 0)
    """

    n_states: ClassVar[int] = 0
    free_rocking_closed_form: ClassVar[bool] = True  # Housner's inverted pendulum

    def __check_init__(self):
        if self.capacity is not None or self.stop is not None:
            raise ValueError(
                "`capacity` and `stop` are an isolator's displacement limit; a "
                "fixed base does not move"
            )

    def initial_state(self):
        return None

    def describe(self):
        return "fixed base"

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
    """Linear viscoelastic isolator, F = k u + c u'.

    The stiffness k = M (2 pi / T_s)^2 (N/m) and the damping coefficient
    c = 2 xi M (2 pi / T_s) (N s/m), with M = m + m_b the total mass of block
    and base: the base with the block in translation vibrates with period T_s
    and damping ratio xi. The base state is (u, u'), in m and m/s. The paper's
    values are T_s = 2 s, xi = 0.35 and a mass ratio of 0.5.

    Args:
        period: T_s, the isolation period (s), > 0.
        damping: xi, the damping ratio (fraction of critical, -), >= 0.
        mass_ratio: m / m_b, block mass over base mass (-), in (0, 1e6].

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jax.numpy as jnp, jaxrock as jr
        >>> base = jr.LinearIsolator(period=2.0, damping=0.35, mass_ratio=0.5)
        >>> base.describe()
        'linear isolator (T_s = 2 s, xi = 0.35, mass ratio 0.5)'
        >>> f = base.force(jnp.array([0.1, 0.0]))  # F / M at u = 0.1 m, u' = 0
        >>> round(float(f), 4)  # (2 pi / T_s)^2 u, in m/s^2
        0.987
    """

    period: Float[Array, "..."] = parameter("period", "s")
    damping: Float[Array, "..."] = parameter("damping", "1")
    mass_ratio: Float[Array, "..."] = parameter("mass_ratio", "1")
    n_states: ClassVar[int] = 2

    def constraints(self):
        return [
            greater_than_zero("period", self.period),
            at_least_zero("damping", self.damping),
            mass_ratio_constraint(self.mass_ratio),
        ]

    def initial_state(self):
        return jnp.zeros(2, dtype=self.period.dtype)

    def describe(self):
        return (
            f"linear isolator (T_s = {describe_values(self.period)} s, "
            f"xi = {describe_values(self.damping)}, "
            f"mass ratio {describe_values(self.mass_ratio)})"
        )

    def force(self, state):
        omega = 2.0 * jnp.pi / self.period
        return omega**2 * state[0] + 2.0 * self.damping * omega * state[1]

    def rates(self, state, u_ddot):
        return jnp.stack([state[1], u_ddot])

    @property
    def _omega(self):
        return 2.0 * jnp.pi / self.period

    def free_vibration_bounds(self, state):
        return free_vibration_bounds(self._omega, self.damping, state)

    def translation_tables(self, samples, dt, length):
        return translation_tables(self._omega, self.damping, samples, dt, length)

    def free_vibration(self, state, tau):
        return free_vibration(self._omega, self.damping, state, tau)

    @property
    def block_mass_fraction(self):
        return self.mass_ratio / (1.0 + self.mass_ratio)


class AbstractBoucWenIsolator(AbstractIsolator):
    """The paper's nonlinear isolator, Eqs. (2.5)-(2.6): a bilinear hysteretic
    force F = K u + Q z, with the dimensionless Bouc-Wen variable z,

        Y z' = A u' - gamma |u'| z |z|^(eta - 1) - beta u' |z|^eta,

    the yield displacement Y (m), the post-yield stiffness K (N/m) and the
    characteristic strength Q (N), the force at which the isolator yields
    (beyond K Y). z is stiff: |z'| reaches |u'| / Y. A subclass gives K / M
    (`stiffness_per_mass`, 1/s^2) and Q / M (`strength_per_mass`, m/s^2), M
    the total mass: `FrictionPendulum` (K = M g / R, Q = mu M g) and
    `BilinearIsolator` (K and Q of a lead-rubber or other bilinear bearing).
    The paper's Bouc-Wen constants are A = 1, gamma = 0.9, beta = 0.1,
    eta = 2.

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.BilinearIsolator(strength=0.05, period=2.5,
        ...                            yield_displacement=0.01, mass_ratio=0.5)
        >>> isinstance(base, jr.AbstractBoucWenIsolator)
        True
        >>> round(float(base.stiffness_per_mass), 4)  # (2 pi / 2.5 s)^2
        6.3165
    """

    mass_ratio: eqx.AbstractVar[Float[Array, "..."]]
    yield_displacement: eqx.AbstractVar[Float[Array, "..."]]
    A: eqx.AbstractVar[Float[Array, "..."]]
    gamma: eqx.AbstractVar[Float[Array, "..."]]
    beta: eqx.AbstractVar[Float[Array, "..."]]
    eta: eqx.AbstractClassVar[float]
    hysteretic_state: ClassVar[bool] = True

    @property
    @abc.abstractmethod
    def stiffness_per_mass(self) -> Float[Array, "..."]:
        """K / M (1/s^2): the post-yield stiffness over the total mass."""

    @property
    @abc.abstractmethod
    def strength_per_mass(self) -> Float[Array, "..."]:
        """Q / M (m/s^2): the characteristic strength over the total mass."""

    def bouc_wen_constraints(self) -> list[Constraint]:
        """The ranges of the parameters every Bouc-Wen isolator has."""
        return [
            mass_ratio_constraint(self.mass_ratio),
            greater_than_zero("yield_displacement", self.yield_displacement),
            greater_than_zero("A", self.A),
            # gamma < 0 (with gamma + beta > 0) is Bouc-Wen's unbounded class:
            # after a reversal z grows on the beta - gamma branch without end.
            at_least_zero("gamma", self.gamma),
            Constraint(
                "beta", self.beta, lambda v: self.gamma + v > 0, "with gamma + beta > 0"
            ),
        ]

    def initial_state(self):
        return jnp.zeros(self.n_states, dtype=self.yield_displacement.dtype)

    @abc.abstractmethod
    def hysteretic(self, state):
        """The Bouc-Wen variable z."""

    def restoring_force(self, u):
        """The elastic part of the force over M (m/s^2): K u / M; the
        derivative of `potential`."""
        return self.stiffness_per_mass * u

    def potential(self, u):
        """The potential of `restoring_force` (m^2/s^2), 0 at u = 0."""
        return 0.5 * self.stiffness_per_mass * u**2

    def displacement_bound(self, energy):
        """The largest |u| (m) at which `potential` is at most `energy`."""
        return jnp.sqrt(2.0 * energy / self.stiffness_per_mass)

    def restoring_bound(self, u_bound):
        """The largest |`restoring_force`| (m/s^2) within |u| <= u_bound."""
        return self.stiffness_per_mass * u_bound

    def force(self, state):
        z = self.hysteretic(state)
        return self.restoring_force(state[0]) + self.strength_per_mass * z

    def free_vibration_bounds(self, state):
        # E = u'^2 / 2 + V(u) + q Y z^2 / (2A) (V: `potential`, q = Q / M)
        # cannot grow when gamma >= |beta| (Bouc-Wen is then dissipative);
        # V(u) <= E bounds |u|, |z| <= sqrt(2 A E / (q Y)) and
        # |F / M| <= max |restoring force| + q |z|.
        u, u_dot, z = state[0], state[1], self.hysteretic(state)
        q = self.strength_per_mass
        energy = (
            0.5 * u_dot**2
            + self.potential(u)
            + 0.5 * q * self.yield_displacement * z**2 / self.A
        )
        energy = jnp.maximum(energy, 1e-300)  # a finite derivative of sqrt at rest
        u_bound = self.displacement_bound(energy)
        # Starting from z = 0, |z| never exceeds z_max = (A / (gamma + beta))^(1/eta).
        z_max = (self.A / (self.gamma + self.beta)) ** (1.0 / self.eta)
        z_bound = jnp.minimum(
            z_max,
            jnp.sqrt(
                2.0 * self.A * energy / jnp.maximum(q * self.yield_displacement, 1e-300)
            ),
        )
        f_bound = self.restoring_bound(u_bound) + q * z_bound
        dissipative = self.gamma >= jnp.abs(self.beta)
        return (
            jnp.where(dissipative, u_bound, jnp.inf),
            jnp.where(dissipative, f_bound, jnp.inf),
        )

    @property
    def block_mass_fraction(self):
        return self.mass_ratio / (1.0 + self.mass_ratio)


class AbstractClosedFormBoucWen(AbstractBoucWenIsolator):
    """A Bouc-Wen isolator with eta = 2, its z exact in closed form.

    Along a monotone stretch of u, Y dz/du = A - c z^2 with c = gamma + beta
    while |z| grows and beta - gamma while it shrinks, so z is an explicit
    function of u from the stretch's start (u_r, z_r). The base state is
    (u, u', u_r, z_r, w0), w0 the travel (in units of Y) after which a
    shrinking |z| passes 0; the memory restarts at each reversal of u' (an
    event) or where an impact reverses u'. Without the stiff z, steps follow
    the motion, not the stiff z (`IntegratedFrictionPendulum` takes several
    times the steps: the docs' performance page).
    """

    eta: ClassVar[float] = 2.0
    n_states: ClassVar[int] = 5
    n_integrated: ClassVar[int] = 2  # u, u'; (u_r, z_r, w0) at transitions

    def hysteretic(self, state):
        """The Bouc-Wen variable z, from the stretch's start (u_r, z_r)."""
        u, u_r, z_r, w0 = state[0], state[2], state[3], state[4]
        d = jnp.sign(u - u_r)
        w = jnp.abs(u - u_r) / self.yield_displacement
        zeta0 = d * z_r  # z along the direction of travel
        a, loading, unloading = self.A, self.gamma + self.beta, self.beta - self.gamma
        shrinking = zeta0 < 0
        # |z| shrinks (c = beta - gamma) up to w0, then grows (c = gamma + beta)
        # from the stretch's start, or from 0 once past w0: one solution on
        # each lane's own piece.
        unloads = shrinking & (w < w0)
        c = jnp.where(unloads, unloading, loading)
        start = jnp.where(shrinking & ~unloads, 0.0, zeta0)
        w_piece = jnp.where(shrinking & ~unloads, w - w0, w)
        num, den = _solution_sine_ratio(c, a, w_piece)
        zeta = (start * den + a * num) / (den + c * start * num)
        # Read by many kernels (the force, the conditions): computed once.
        return computed_once(jnp.where(d == 0, z_r, d * zeta))

    def rates(self, state, u_ddot):
        zero = jnp.zeros_like(u_ddot)
        return jnp.stack([state[1], u_ddot, zero, zero, zero])

    def at_transition(self, state, turned):
        """With z in closed form: a new stretch (u_r, z_r) = (u, z) where u'
        turns back, at a located reversal (`turned`; u' is zero there to
        rounding, of either sign) or where an impact reverses u'."""
        u, u_dot, u_r = state[0], state[1], state[2]
        direction = jnp.sign(u - u_r)  # of the stretch so far
        back = (turned & (u != u_r)) | self.turns_back(state)
        new_direction = jnp.where(turned, -direction, jnp.sign(u_dot))
        z = self.hysteretic(state)
        # |z| shrinks first (to 0 after a travel w0) if z points against it.
        shrink = jnp.maximum(-new_direction * z, 0.0)
        w0 = _solution_sine_inverse(self.beta - self.gamma, self.A, shrink / self.A)
        return jnp.where(back, jnp.stack([u, u_dot, u, z, w0]), state)

    def turns_back(self, state):
        u, u_dot, u_r = state[0], state[1], state[2]
        return (jnp.sign(u - u_r) * u_dot < 0) & (u != u_r)

    def peak_condition(self):
        # Every reversal of u' starts a new stretch, and includes the peaks.
        return condition_reversal


class AbstractFrictionPendulum(AbstractBoucWenIsolator):
    """Friction pendulum system with Bouc-Wen hysteresis, F = K u + Q z.

    The pendulum stiffness K = M g / R (N/m) and the friction force
    Q = mu M g (N), with M = m + m_b the total mass of block and base, the
    friction coefficient mu and the radius R (m) of the sliding surface; z
    as in `AbstractBoucWenIsolator`.
    `FrictionPendulum` (eta = 2) has z in closed form;
    `IntegratedFrictionPendulum` integrates it (any eta >= 1). Both take the
    parameters mu, R, m / m_b, Y, A, gamma and beta (see `FrictionPendulum`).
    The paper uses mu = 0.11, R = 2.24 m, a mass ratio of 0.5, A = 1,
    gamma = 0.9, beta = 0.1, eta = 2 and Y = 0.5 mm.

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.FrictionPendulum(friction=0.11, radius=2.24, mass_ratio=0.5)
        >>> isinstance(base, jr.AbstractFrictionPendulum), base.eta
        (True, 2.0)
    """

    weight_borne: ClassVar[bool] = True

    friction: Float[Array, "..."] = parameter("friction", "1")
    radius: Float[Array, "..."] = parameter("radius", "m")
    mass_ratio: Float[Array, "..."] = parameter("mass_ratio", "1")
    yield_displacement: Float[Array, "..."] = parameter(
        "yield_displacement", "m", default=5e-4
    )
    A: Float[Array, "..."] = parameter("A", "1", default=1.0)
    gamma: Float[Array, "..."] = parameter("gamma", "1", default=0.9)
    beta: Float[Array, "..."] = parameter("beta", "1", default=0.1)

    def constraints(self):
        return [
            at_least_zero("friction", self.friction),
            greater_than_zero("radius", self.radius),
        ] + self.bouc_wen_constraints()

    def describe(self):
        return (
            f"friction pendulum (mu = {describe_values(self.friction)}, "
            f"R = {describe_values(self.radius)} m, "
            f"mass ratio {describe_values(self.mass_ratio)})"
        )

    @property
    def stiffness_per_mass(self):
        return GRAVITY / self.radius

    @property
    def strength_per_mass(self):
        return self.friction * GRAVITY

    @property
    def geometric_limit(self):
        # A dish of radius R holds the slider within |u| < R (a hemisphere;
        # a real dish far less): K u = M g u / R assumes |u| << R.
        return self.radius

    def force(self, state):
        # g (u / R + mu z): K u + Q z over M, in the arithmetic of the
        # friction pendulum's maps as published in the documentation.
        return GRAVITY * (
            state[0] / self.radius + self.friction * self.hysteretic(state)
        )


class FrictionPendulum(AbstractFrictionPendulum, AbstractClosedFormBoucWen):
    """Friction pendulum, F = K u + Q z, with its Bouc-Wen z exact in closed form.

    K = M g / R (N/m) and Q = mu M g (N) as in `AbstractFrictionPendulum`,
    with eta = 2 and z as in `AbstractClosedFormBoucWen`. The base state is
    (u, u', u_r, z_r, w0). It is the `BilinearIsolator` of the same K, Q
    and Y.

    Args:
        friction: mu, the friction coefficient (-), >= 0.
        radius: R, the radius of curvature of the sliding surface (m), > 0.
        mass_ratio: m / m_b, block mass over base mass (-), in (0, 1e6].
        yield_displacement: Y (m), > 0; default 5e-4.
        A: the Bouc-Wen A (-), > 0; default 1.
        gamma: the Bouc-Wen gamma (-), >= 0; default 0.9.
        beta: the Bouc-Wen beta (-), with gamma + beta > 0; default 0.1.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.FrictionPendulum(friction=0.11, radius=2.24, mass_ratio=0.5)
        >>> base.describe()
        'friction pendulum (mu = 0.11, R = 2.24 m, mass ratio 0.5)'
        >>> state = base.initial_state()  # (u, u', u_r, z_r, w0) at rest
        >>> state = state.at[0].set(0.01)  # u = 0.01 m = 20 Y past the start
        >>> round(float(base.hysteretic(state)), 6)  # z: the pendulum slides
        1.0
    """


class BilinearIsolator(AbstractClosedFormBoucWen):
    """A bilinear hysteretic isolator (a lead-rubber or high-damping rubber
    bearing, a steel damper), F = K u + Q z with the paper's Bouc-Wen z,
    exact in closed form (eta = 2, `AbstractClosedFormBoucWen`).

    K = M (2 pi / T)^2 (N/m), the post-yield stiffness, and Q = q M g (N), the
    characteristic strength, M = m + m_b. The force-displacement loop is
    bilinear: stiffness K + Q / Y up to the yield displacement Y, then K. Unlike
    a friction pendulum's, K and Q do not depend on the normal force. A
    friction pendulum is the special case T = 2 pi sqrt(R / g), q = mu.

    Args:
        strength: q = Q / (M g), the characteristic strength over the weight
            (-), >= 0 (lead-rubber bearings: about 0.03-0.1).
        period: T, the period of the post-yield stiffness (s), > 0.
        yield_displacement: Y (m), > 0 (lead-rubber bearings: about 0.01-0.03).
        mass_ratio: m / m_b, block mass over base mass (-), in (0, 1e6].
        A: the Bouc-Wen A (-), > 0; default 1.
        gamma: the Bouc-Wen gamma (-), >= 0; default 0.9.
        beta: the Bouc-Wen beta (-), with gamma + beta > 0; default 0.1.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.BilinearIsolator(strength=0.06, period=2.5,
        ...                            yield_displacement=0.015, mass_ratio=0.5)
        >>> base.describe()
        'bilinear isolator (Q / Mg = 0.06, T = 2.5 s, Y = 0.015 m, mass ratio 0.5)'
        >>> r = jr.simulate(jr.Block(4.0, 1.0), base,
        ...                 jr.near_fault_pulse("Northridge JFA/SN"))
        >>> jr.Outcome(int(r.outcome)).name, bool(r.ok)
        ('OVERTURNED', True)
    """

    strength: Float[Array, "..."] = parameter("strength", "1")
    period: Float[Array, "..."] = parameter("period", "s")
    yield_displacement: Float[Array, "..."] = parameter("yield_displacement", "m")
    mass_ratio: Float[Array, "..."] = parameter("mass_ratio", "1")
    A: Float[Array, "..."] = parameter("A", "1", default=1.0)
    gamma: Float[Array, "..."] = parameter("gamma", "1", default=0.9)
    beta: Float[Array, "..."] = parameter("beta", "1", default=0.1)

    def constraints(self):
        return [
            at_least_zero("strength", self.strength),
            greater_than_zero("period", self.period),
        ] + self.bouc_wen_constraints()

    def describe(self):
        return (
            f"bilinear isolator (Q / Mg = {describe_values(self.strength)}, "
            f"T = {describe_values(self.period)} s, "
            f"Y = {describe_values(self.yield_displacement)} m, "
            f"mass ratio {describe_values(self.mass_ratio)})"
        )

    @property
    def stiffness_per_mass(self):
        return (2.0 * jnp.pi / self.period) ** 2

    @property
    def strength_per_mass(self):
        return self.strength * GRAVITY


class SphericalRollingIsolator(AbstractClosedFormBoucWen):
    """Balls rolling in spherical dishes (a rolling isolation platform under
    a display case or a statue): a rolling pendulum.

    The platform rises on the dishes' profile as it moves, so the restoring
    force is that of a pendulum, K = M g / R, R the radius of the path of
    the balls' centres (for a ball of radius r in a dish of radius R_d,
    R = R_d - r; with a dish above and below each ball the platform moves
    twice as far, R = 2 (R_d - r)). The isolation period 2 pi sqrt(R / g)
    does not depend on the amplitude. The rolling resistance is a small
    friction, Q = mu_r M g (mu_r about 0.001-0.01 for steel balls on steel,
    more on rubber-coated dishes), smoothed by the paper's Bouc-Wen z as a
    friction pendulum's friction is (`AbstractClosedFormBoucWen`). This is
    the one-degree-of-freedom reduction of the rolling isolation systems
    that Harvey and Gavin model (balls in shallow bowls, whose profile h(u)
    gives the restoring force M g dh/du), without the platform's rotation.
    The balls cannot pass |u| = R (`geometric_limit`: CAPACITY_EXCEEDED); a
    real dish's rim is nearer, a `capacity`.

    Args:
        radius: R, the radius of the path of the balls' centres (m), > 0.
        rolling_resistance: mu_r, the rolling resistance coefficient (-), >= 0.
        mass_ratio: m / m_b, block mass over platform mass (-), > 0.
        yield_displacement: Y (m), the travel over which the rolling resistance
            builds up, > 0; default 5e-4.
        A: the Bouc-Wen A (-), > 0; default 1.
        gamma: the Bouc-Wen gamma (-), >= 0; default 0.9.
        beta: the Bouc-Wen beta (-), with gamma + beta > 0; default 0.1.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.SphericalRollingIsolator(radius=1.0, rolling_resistance=0.005,
        ...                                    mass_ratio=1.0)
        >>> base.describe()
        'spherical rolling isolator (R = 1 m, mu_r = 0.005, mass ratio 1)'
    """

    weight_borne: ClassVar[bool] = True

    radius: Float[Array, "..."] = parameter("radius", "m")
    rolling_resistance: Float[Array, "..."] = parameter("rolling_resistance", "1")
    mass_ratio: Float[Array, "..."] = parameter("mass_ratio", "1")
    yield_displacement: Float[Array, "..."] = parameter(
        "yield_displacement", "m", default=5e-4
    )
    A: Float[Array, "..."] = parameter("A", "1", default=1.0)
    gamma: Float[Array, "..."] = parameter("gamma", "1", default=0.9)
    beta: Float[Array, "..."] = parameter("beta", "1", default=0.1)

    def constraints(self):
        return [
            greater_than_zero("radius", self.radius),
            at_least_zero("rolling_resistance", self.rolling_resistance),
        ] + self.bouc_wen_constraints()

    def describe(self):
        return (
            f"spherical rolling isolator (R = {describe_values(self.radius)} m, "
            f"mu_r = {describe_values(self.rolling_resistance)}, "
            f"mass ratio {describe_values(self.mass_ratio)})"
        )

    @property
    def stiffness_per_mass(self):
        return GRAVITY / self.radius

    @property
    def strength_per_mass(self):
        return self.rolling_resistance * GRAVITY

    @property
    def geometric_limit(self):
        # The balls' centres move on a circle of radius R: |u| < R (a real
        # dish far less), and K u = M g u / R assumes |u| << R.
        return self.radius


class ConicalRollingIsolator(AbstractClosedFormBoucWen):
    """Balls rolling in conical dishes (ball-in-cone isolators): a constant
    restoring force.

    On a cone of slope s (the tangent of its angle to the horizontal) the
    restoring force is M g s, whatever the displacement: the isolated object
    has no natural period of its own, and the time it takes to swing back
    grows with the amplitude (a free oscillation of amplitude a lasts
    4 sqrt(2 a / (g s)) without resistance), so no frequency of the ground
    motion tunes to it. The force stays below M g (s + mu_r) at any
    displacement: the cone caps the acceleration the object feels. The
    cone's apex is rounded: the dish's height is s sqrt(u^2 + d^2) (a
    hyperboloid whose apex has the radius of curvature d / s), so the force
    M g s u / sqrt(u^2 + d^2) is smooth at u = 0. The rolling resistance is a
    small friction, Q = mu_r M g, smoothed by the paper's Bouc-Wen z
    (`AbstractClosedFormBoucWen`), as in `SphericalRollingIsolator`.

    Args:
        slope: s, the cone's slope (-), > 0 (about 0.02-0.1).
        rolling_resistance: mu_r, the rolling resistance coefficient (-), >= 0.
        mass_ratio: m / m_b, block mass over platform mass (-), > 0.
        apex: d, the half-width of the rounded apex (m), > 0; default 1e-3.
        yield_displacement: Y (m), > 0; default 5e-4.
        A: the Bouc-Wen A (-), > 0; default 1.
        gamma: the Bouc-Wen gamma (-), >= 0; default 0.9.
        beta: the Bouc-Wen beta (-), with gamma + beta > 0; default 0.1.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.ConicalRollingIsolator(slope=0.05, rolling_resistance=0.005,
        ...                                  mass_ratio=1.0)
        >>> round(float(base.restoring_force(0.1)), 4)  # 10 cm out: ~ g s (m/s^2)
        0.4905
    """

    weight_borne: ClassVar[bool] = True

    slope: Float[Array, "..."] = parameter("slope", "1")
    rolling_resistance: Float[Array, "..."] = parameter("rolling_resistance", "1")
    mass_ratio: Float[Array, "..."] = parameter("mass_ratio", "1")
    apex: Float[Array, "..."] = parameter("apex", "m", default=1e-3)
    yield_displacement: Float[Array, "..."] = parameter(
        "yield_displacement", "m", default=5e-4
    )
    A: Float[Array, "..."] = parameter("A", "1", default=1.0)
    gamma: Float[Array, "..."] = parameter("gamma", "1", default=0.9)
    beta: Float[Array, "..."] = parameter("beta", "1", default=0.1)

    def constraints(self):
        return [
            greater_than_zero("slope", self.slope),
            at_least_zero("rolling_resistance", self.rolling_resistance),
            greater_than_zero("apex", self.apex),
        ] + self.bouc_wen_constraints()

    def describe(self):
        return (
            f"conical rolling isolator (slope {describe_values(self.slope)}, "
            f"mu_r = {describe_values(self.rolling_resistance)}, "
            f"mass ratio {describe_values(self.mass_ratio)})"
        )

    @property
    def stiffness_per_mass(self):
        """The stiffness at the rounded apex over M, g s / d (1/s^2)."""
        return GRAVITY * self.slope / self.apex

    @property
    def strength_per_mass(self):
        return self.rolling_resistance * GRAVITY

    def restoring_force(self, u):
        return GRAVITY * self.slope * u / jnp.sqrt(u * u + self.apex**2)

    def potential(self, u):
        # g s (sqrt(u^2 + d^2) - d), without cancellation near the apex.
        root = jnp.sqrt(u * u + self.apex**2)
        return GRAVITY * self.slope * u * u / (root + self.apex)

    def displacement_bound(self, energy):
        height = energy / (GRAVITY * self.slope) + self.apex
        return jnp.sqrt(jnp.maximum(height**2 - self.apex**2, 0.0))

    def restoring_bound(self, u_bound):
        return self.restoring_force(u_bound)


class IntegratedFrictionPendulum(AbstractFrictionPendulum):
    """Friction pendulum, F = K u + Q z, its Bouc-Wen z integrated for any eta >= 1.

    K = M g / R (N/m) and Q = mu M g (N), and
    Y z' = A u' - gamma |u'| z |z|^(eta - 1) - beta u' |z|^eta as in
    `AbstractFrictionPendulum`. The base state is (u, u', z), in m, m/s and -.
    z is stiff (|z'| reaches |u'| / Y), so the solver takes steps of the
    order of Y / |u'| (s) while the base slides: prefer `FrictionPendulum`
    where eta = 2.
    `eta` is static: each value compiles once.

    Args:
        friction: mu, the friction coefficient (-), >= 0.
        radius: R, the radius of curvature of the sliding surface (m), > 0.
        mass_ratio: m / m_b, block mass over base mass (-), in (0, 1e6].
        yield_displacement: Y (m), > 0; default 5e-4.
        A: the Bouc-Wen A (-), > 0; default 1.
        gamma: the Bouc-Wen gamma (-), >= 0; default 0.9.
        beta: the Bouc-Wen beta (-), with gamma + beta > 0; default 0.1.
        eta: the Bouc-Wen exponent (-), >= 1; default 2.

    Raises:
        ValueError: a concrete parameter that is not a real number or lies
            outside its range (the message names the parameter and the range).

    Examples:
        >>> import jaxrock as jr
        >>> base = jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5, eta=1.5)
        >>> base.initial_state().shape, base.eta
        ((3,), 1.5)
    """

    eta: float = eqx.field(default=2.0, static=True, converter=_static_eta)
    n_states: ClassVar[int] = 3

    def constraints(self):
        return super().constraints() + [
            Constraint("eta", self.eta, lambda v: v >= 1, "finite and >= 1")
        ]

    def hysteretic(self, state):
        return state[2]

    def rates(self, state, u_ddot):
        u_dot = state[1]
        z = state[2]
        abs_z = jnp.abs(z)
        # |z|^(eta - 1) (|z|^eta = |z| power: one pow, not two), 0 at z = 0
        # (1 for eta = 1) through a safe base: pow's derivative at 0,
        # (eta - 1) 0^(eta - 2), is inf for eta < 2, and times a zero
        # tangent NaN, in every forward-mode derivative from rest.
        if self.eta == 1.0:
            power = jnp.ones_like(abs_z)
        else:
            moving = abs_z > 0
            safe = jnp.where(moving, abs_z, 1.0)
            power = jnp.where(moving, safe ** (self.eta - 1.0), 0.0)
        z_dot = (
            self.A * u_dot
            - self.gamma * jnp.abs(u_dot) * z * power
            - self.beta * u_dot * abs_z * power
        ) / self.yield_displacement
        return jnp.stack([u_dot, u_ddot, z_dot])


def _solution_sine_ratio(c, a, w):
    """S(w) = num / den, with S(0) = 0 and S' = 1 - a c S^2, for w >= 0:
    tanh(q w) / q (a c = q^2 > 0), tan(q w) / q (a c = -q^2 < 0), w (c = 0).
    Then zeta(w) = (zeta0 + a S) / (1 + c zeta0 S) solves zeta' = a - c zeta^2.
    tanh by `exp` and tan by the polynomial `sincos`: XLA's float64 tanh,
    tan and arctan are scalar library calls, slow on the CPU. A ratio, so
    that zeta takes one division."""
    x = a * c * w * w
    q = jnp.sqrt(jnp.abs(a * c))
    e = jnp.exp(-2.0 * q * w)
    sin, cos = sincos(q * w)
    small = jnp.abs(x) < 1e-12
    num = jnp.where(small, w * (1.0 - x / 3.0), jnp.where(x > 0, 1.0 - e, sin))
    den = jnp.where(small, 1.0, jnp.where(x > 0, 1.0 + e, cos) * q)
    return num, den


def _solution_sine_inverse(c, a, v):
    """w >= 0 with S(w) = v >= 0 (see `_solution_sine_ratio`)."""
    x = a * c * v * v
    q = jnp.sqrt(jnp.abs(a * c))
    safe_q = jnp.where(q == 0, 1.0, q)
    big = jnp.where(x > 0, jnp.arctanh(safe_q * v), jnp.arctan(safe_q * v)) / safe_q
    return jnp.where(jnp.abs(x) < 1e-12, v * (1.0 + x / 3.0), big)


def condition_reversal(t, y, args, **kwargs):
    """> 0 while u moves away from the stretch's start u_r; fires where u'
    turns back (a memory isolator's reversal)."""
    del t, kwargs
    u, u_dot, u_r = y[2][0], y[2][1], y[2][2]
    return jnp.sign(u - u_r) * u_dot
