"""The flat loop of behavior maps: one solver step per iteration, events inside.

A vmapped loop costs its slowest lane at every iteration. With one Diffrax solve
per segment (`simulate`), an iteration lasts as long as the longest segment of
any lane, and segments are short and uneven (uplift, apex, impact, new peaks of
|u|): about half the executed lane-steps were waiting, and each segment paid a
solve's set-up. Here an iteration advances every lane by one step attempt of
the same solver and controller (Tsit5 and Diffrax's PIDController by default);
the same event conditions are checked at the step's end, an event is located
on the step's dense output by bracketed Newton, and `_transition` applies it
exactly as in the segment loop. `_maps._map_chunk` refills finished lanes.
"""

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp

from ._dynamics import vector_field
from ._simulate import _setup, _transition

# Newton iterations of an event's root find (kept in a bracket, from the secant
# guess). 8 reproduce the paper's maps to 3e-14 against 14; 5 are too few (near
# double roots of theta' the bracket falls back to bisection).
_NEWTON = 8


def _clip(t0, t1, times):
    """The first of `times` after t0, if it comes before t1 (Diffrax's step_ts)."""
    if times is None:
        return t1
    i = jnp.searchsorted(times, t0, side="right")
    nxt = times[jnp.minimum(i, times.shape[0] - 1)]
    return jnp.where((i < times.shape[0]) & (nxt < t1), nxt, t1)


class _StepSolution:
    """What `_transition` reads of a Diffrax solution, for one step."""

    def __init__(self, t, y, result, event_mask, steps):
        self.ts = t[None]
        self.ys = jax.tree_util.tree_map(lambda x: x[None], y)
        self.result = result
        self.event_mask = event_mask
        self.stats = {"num_steps": steps}


def flat_step(c, block, base, motion, duration, opts):
    """One step attempt of one lane; returns the new carry (as `_transition`)."""
    active, args, conditions, t_stop, dtmax, controller = _setup(
        c, block, base, motion, duration, opts
    )
    dtmax = jnp.inf if dtmax is None else dtmax
    term = diffrax.ODETerm(vector_field)
    solver = opts.solver
    t0, y0 = c.t, c.y
    t1 = jnp.minimum(t0 + jnp.minimum(c.dt, dtmax), t_stop)
    t1 = _clip(t0, _clip(t0, t1, motion.step_ts), motion.jump_ts)
    t1 = jnp.where(active, t1, t0 + 1.0)  # a frozen lane: a harmless dummy step
    state = solver.init(term, t0, t1, y0, args)
    y1, y_error, dense, _, solver_result = solver.step(
        term, t0, t1, y0, args, state, made_jump=False
    )
    _, ctrl_state = controller.init(term, t0, t1, y0, t1 - t0, args, None, None)
    keep, next_t0, next_t1, _, _, ctrl_result = controller.adapt_step_size(
        t0, t1, y0, y1, args, y_error, solver.error_order(term), ctrl_state
    )
    # Events: the first condition (in order) that goes from > 0 to <= 0.
    fired, earlier = [], jnp.asarray(False)
    v0s = [cond(t0, y0, args) for cond in conditions]
    v1s = [cond(t1, y1, args) for cond in conditions]
    for v0, v1 in zip(v0s, v1s):
        hit = keep & (v0 > 0) & (v1 <= 0) & ~earlier
        fired.append(hit)
        earlier = earlier | hit
    event = earlier
    interp = solver.interpolation_cls(t0=t0, t1=t1, **dense)

    def g(t):
        y = interp.evaluate(t)
        return sum(
            jnp.where(h, cond(t, y, args), 0.0) for h, cond in zip(fired, conditions)
        )

    def locate():
        """Bracketed Newton on [t0, t1] (g > 0 at t0, <= 0 at t1) from the secant."""
        g0 = sum(jnp.where(h, v, 0.0) for h, v in zip(fired, v0s))
        g1 = sum(jnp.where(h, v, 0.0) for h, v in zip(fired, v1s))
        lower, upper = t0, t1
        t = t0 + (t1 - t0) * g0 / jnp.where(g0 - g1 == 0, 1.0, g0 - g1)
        t = jnp.clip(jnp.where(event, t, t1), t0, t1)
        for _ in range(_NEWTON):
            value, slope = jax.jvp(g, (t,), (jnp.ones_like(t),))
            positive = value > 0
            lower = jnp.where(positive, t, lower)
            upper = jnp.where(positive, upper, t)
            newton = t - value / jnp.where(slope == 0, 1.0, slope)
            # Inclusive bounds: a converged Newton step (t itself) stays put.
            inside = (slope != 0) & (newton >= lower) & (newton <= upper)
            inside = inside & jnp.isfinite(newton)
            bisect = 0.5 * (lower + upper)
            t = jnp.where(value == 0, t, jnp.where(inside, newton, bisect))
        return t, interp.evaluate(t)

    # Most iterations see no event in any lane: skip the root find then.
    t_event, y_event = jax.lax.cond(eqxi.unvmap_any(event), locate, lambda: (t1, y1))
    t_end = jnp.where(event, t_event, jnp.where(keep, t1, t0))
    y_end = jax.tree_util.tree_map(
        lambda a, b, e: jnp.where(event, e, jnp.where(keep, a, b)), y1, y0, y_event
    )
    result = diffrax.RESULTS.where(
        event, diffrax.RESULTS.event_occurred, diffrax.RESULTS.successful
    )
    failed = (solver_result != diffrax.RESULTS.successful) | (
        ctrl_result != diffrax.RESULTS.successful
    )
    result = diffrax.RESULTS.where(failed, diffrax.RESULTS.internal_error, result)
    sol = _StepSolution(t_end, y_end, result, fired, jnp.asarray(1))
    new = _transition(c, sol, block, base, motion, duration, opts)
    # The next step: the controller's proposal (not the mean step of a segment).
    return eqx.tree_at(lambda n: n.dt, new, jnp.where(active, next_t1 - next_t0, c.dt))
