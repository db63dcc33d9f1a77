"""Step-size control: an integral controller, and steps that end at a motion's
kinks.

Both engines use `StepSizeController` (wrapped in `KinkClip` under a motion
with kinks): `simulate` through `diffrax.diffeqsolve`, the flat loop of maps
by calling `adapt_step_size` on its lanes, so both take the same steps.
"""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array

from ._signal import AbstractSignal

# Diffrax's `PIDController` defaults.
_SAFETY = 0.9
_FACTOR_MIN = 0.2
_FACTOR_MAX = 10.0
# The smallest step (s, relative to max(|t|, 1 s)) a rejected step may
# propose: below it the solve has failed.
_SMALLEST_STEP = 1e-14


class StepSizeController(diffrax.AbstractAdaptiveStepSizeController):
    """The integral controller of `diffrax.PIDController` at its defaults.

    A step of size h from y0 to y1 with error estimate e is kept if

        err = RMS(e / (atol + rtol max(|y0|, |y1|))) < 1,

    and the next step (from y1 if kept, else again from y0) has size
    h clip(0.9 err^(-1/q), 1, 10) if kept, h clip(0.9 err^(-1/q), 0.2, 0.9)
    if not, at most `dtmax` (q: the solver's error order). The power is
    exp(-log(err) / q): XLA vectorizes exp and log over lanes, where a
    float64 power is a scalar library call per lane (5% of the fixed base's
    record map). Derivatives do not flow through step sizes. A NaN error
    rejects the step (shrunk by 0.2); a rejected step that would shrink
    below 1e-14 max(|t|, 1 s) ends the solve as failed (`dt_min_reached`:
    `Status.SOLVER_FAILED`), as where the vector field is not finite.
    """

    rtol: float
    atol: float
    dtmax: Array | None = None

    @property
    def norm(self):
        return optx.rms_norm

    def wrap(self, direction):
        return self

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        if dt0 is None:
            raise ValueError("StepSizeController needs a first step dt0")
        if self.dtmax is not None:
            dt0 = jnp.minimum(dt0, self.dtmax)
        return t0 + dt0, None

    def adapt_step_size(self, t0, t1, y0, y1, args, y_error, error_order, state):
        def scaled(a, b, error):
            b = jnp.where(jnp.isnan(b).any(), a, b)
            return error / (self.atol + jnp.maximum(jnp.abs(a), jnp.abs(b)) * self.rtol)

        error = self.norm(jax.tree_util.tree_map(scaled, y0, y1, y_error))
        # A NaN error (a vector field that gave NaN) rejects the step and
        # shrinks the next by the most.
        error = jnp.where(jnp.isnan(error), jnp.inf, error)
        keep = error < 1
        inverse = jax.lax.stop_gradient(1 / error)
        factor = _SAFETY * jnp.exp(jnp.log(inverse) / error_order)
        factor = jnp.clip(
            factor,
            min=jnp.where(keep, 1.0, _FACTOR_MIN),
            max=jnp.where(keep, _FACTOR_MAX, _SAFETY),
        )
        dt = (t1 - t0) * jax.lax.stop_gradient(factor)
        if self.dtmax is not None:
            dt = jnp.minimum(dt, self.dtmax)
        next_t0 = jnp.where(keep, t1, t0)
        # A rejected step shrunk below any useful size (the vector field is
        # not finite there): the solve has failed, not run out of steps.
        stalled = ~keep & (dt < _SMALLEST_STEP * jnp.maximum(jnp.abs(t0), 1.0))
        result = diffrax.RESULTS.where(
            stalled, diffrax.RESULTS.dt_min_reached, diffrax.RESULTS.successful
        )
        return keep, next_t0, next_t0 + dt, False, state, result


class KinkClip(diffrax.AbstractAdaptiveStepSizeController):
    """A step-size controller whose steps end at the motion's kinks (a
    record's sample times; `AbstractSignal.step_end`), as Diffrax's
    `step_ts` do, but with the next kink found from the step's start alone
    (`next_kink`): `step_ts` sorts and searches all of them in every solve, a
    cost that grew with the record."""

    controller: StepSizeController
    motion: AbstractSignal
    # A block at rest: its level at g (`_model.quiet_level`), lowered at each
    # step to the least g_eff from its start (`level_from`); else None.
    quiet_below: jax.Array | None = None

    def _quiet_below(self, t):
        if self.quiet_below is None:
            return None
        return self.motion.level_from(self.quiet_below, t)

    @property
    def rtol(self):
        return self.controller.rtol

    @property
    def atol(self):
        return self.controller.atol

    @property
    def norm(self):
        return self.controller.norm

    def wrap(self, direction):
        return eqx.tree_at(
            lambda s: s.controller, self, self.controller.wrap(direction)
        )

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        t1, state = self.controller.init(
            terms, t0, t1, y0, dt0, args, func, error_order
        )
        kink = self.motion.next_kink(t0, self._quiet_below(t0))
        return self.motion.step_end(t0, t1 - t0, kink), state

    def adapt_step_size(self, t0, t1, y0, y1, args, y_error, error_order, state):
        keep, next_t0, next_t1, made_jump, state, result = (
            self.controller.adapt_step_size(
                t0, t1, y0, y1, args, y_error, error_order, state
            )
        )
        kink = self.motion.next_kink(next_t0, self._quiet_below(next_t0))
        next_t1 = self.motion.step_end(next_t0, next_t1 - next_t0, kink)
        return keep, next_t0, next_t1, made_jump, state, result
