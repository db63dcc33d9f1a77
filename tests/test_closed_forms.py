"""Closed forms and invariants of the model (docs/model.md)."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq

import jaxrock as jr

G = 9.81
PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


@pytest.fixture(scope="module")
def fixed_rocking():
    """A slender block on a fixed base that rocks with many impacts."""
    block = jr.Block(6.0, 2.0)
    return block, jr.simulate(
        block,
        jr.FixedBase(),
        PULSE,
        history=True,
        rtol=1e-10,
        atol=1e-12,
        duration=25.0,
    )


@pytest.fixture(scope="module")
def linear_rocking():
    block = jr.Block(3.0, 0.5)
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    return (
        block,
        base,
        jr.simulate(block, base, PULSE, history=True, rtol=1e-10, atol=1e-12),
    )


def _at(h, t):
    """Indices of the (pre, post) samples of an event at time t."""
    idx = np.flatnonzero(h.t == t)
    return idx[0], idx[-1]


def test_housner_free_rocking_quarter_period(fixed_rocking):
    """After the pulse, apex -> impact takes the energy-integral time of free fall."""
    block, r = fixed_rocking
    h = r.history
    p, alpha = float(block.p), float(block.alpha)
    checked = 0
    for i, (t, kind) in enumerate(zip(h.event_times, h.event_kinds)):
        if kind != "apex" or t <= float(PULSE.end_time) or i + 1 >= len(h.event_kinds):
            continue
        assert h.event_kinds[i + 1] in ("impact", "rest")
        th_a = float(abs(h.theta[_at(h, t)[0]]))

        # t = int_0^th_a dth / sqrt(2 p^2 (cos(alpha - th_a) - cos(alpha - th)))
        def g(th):
            if th_a - th < 1e-9:  # the limit at the apex
                return 1.0 / math.sqrt(2 * p**2 * math.sin(alpha - th_a))
            return math.sqrt(
                (th_a - th)
                / (2 * p**2 * (math.cos(alpha - th_a) - math.cos(alpha - th)))
            )

        expected, _ = quad(
            g, 0.0, th_a, weight="alg", wvar=(0.0, -0.5), epsabs=1e-13, epsrel=1e-12
        )
        assert abs((h.event_times[i + 1] - t) - expected) < 1e-8
        checked += 1
    assert checked >= 3


def test_fixed_base_impact_ratio(fixed_rocking):
    block, r = fixed_rocking
    h = r.history
    e = 1 - 1.5 * math.sin(float(block.alpha)) ** 2
    impacts = [t for t, k in zip(h.event_times, h.event_kinds) if k == "impact"]
    assert len(impacts) >= 3
    for t in impacts:
        pre, post = _at(h, t)
        assert h.theta_dot[post] == pytest.approx(e * h.theta_dot[pre], rel=1e-12)
        assert h.theta[post] == 0.0


def test_isolated_impact_momentum_energy_and_eq_2_13(linear_rocking):
    block, base, r = linear_rocking
    h = r.history
    m, mb = 1.0, 1.0 / float(base.mass_ratio)
    M = m + mb
    b, hh, size = float(block.b), float(block.h), float(block.size)
    den = 4 * mb * hh**2 + 4 * mb * b**2 + m * hh**2 + 4 * m * b**2
    num = 4 * mb * hh**2 - 2 * mb * b**2 + m * hh**2 - 2 * m * b**2
    J = 4.0 / 3.0 * m * size**2
    n_impacts = 0
    for t, kind in zip(h.event_times, h.event_kinds):
        if kind not in ("impact", "rest"):
            continue
        n_impacts += 1
        pre, post = _at(h, t)
        momentum = [M * h.u_dot[i] + m * hh * h.theta_dot[i] for i in (pre, post)]
        assert momentum[1] == pytest.approx(momentum[0], rel=1e-12, abs=1e-14)
        energy = [
            0.5 * M * h.u_dot[i] ** 2
            + m * hh * h.u_dot[i] * h.theta_dot[i]
            + 0.5 * J * h.theta_dot[i] ** 2
            for i in (pre, post)
        ]
        assert energy[1] <= energy[0] * (1 + 1e-12)
        if kind == "impact":
            assert h.theta_dot[post] == pytest.approx(
                num / den * h.theta_dot[pre], rel=1e-12
            )
        else:
            assert h.theta_dot[post] == 0.0
    assert n_impacts >= 5


def test_uplift_at_threshold_fixed_and_isolated(fixed_rocking, linear_rocking):
    block, r = fixed_rocking
    t_up = float(r.uplift_time)
    a = float(PULSE.acceleration(t_up))
    assert abs(a) == pytest.approx(G / float(block.slenderness), rel=1e-9)
    block, base, r = linear_rocking
    h = r.history
    i = _at(h, float(r.uplift_time))[0]
    w = 2 * math.pi / float(base.period)
    force = w**2 * h.u[i] + 2 * float(base.damping) * w * h.u_dot[i]
    assert abs(force) == pytest.approx(G / float(block.slenderness), rel=1e-9)


@pytest.mark.parametrize(
    "base", [jr.FixedBase(), jr.LinearIsolator(2.0, 0.35, 0.5)], ids=["fixed", "linear"]
)
def test_no_rocking_below_threshold(base):
    """b/h above max|u'' + x_g''| / g: never rocks; just below: rocks."""
    # Peak absolute base acceleration of the base alone (a squat block never lifts).
    squat = jr.simulate(jr.Block(0.05, 1.0), base, PULSE, history=True)
    h = squat.history
    if isinstance(base, jr.FixedBase):
        ts = np.linspace(0, float(PULSE.end_time), 200001)
        peak = float(np.max(np.abs(np.asarray(PULSE.acceleration(ts)))))
    else:
        w = 2 * math.pi / float(base.period)
        peak = np.max(np.abs(w**2 * h.u + 2 * float(base.damping) * w * h.u_dot))
    lam_star = G / peak
    calm = jr.simulate(jr.Block(lam_star * 0.98, 1.0), base, PULSE)
    rocks = jr.simulate(jr.Block(lam_star * 1.02, 1.0), base, PULSE)
    assert int(calm.outcome) == jr.Outcome.NO_ROCKING
    assert int(rocks.outcome) != jr.Outcome.NO_ROCKING


def test_an_uplift_shorter_than_a_step_is_found():
    """A pulse whose |x_g''| exceeds g tan(alpha) by 0.02% for about 20 ms (the
    pulse fitted to El Centro #6 and lambda = 5.9): a block at rest on a fixed
    base steps only as far as |x_g''| cannot reach the threshold, so the
    excursion cannot hide between two step ends; 0.01% below it, no uplift.
    The same in a map, whose pilots run the translation phase."""
    pulse = jr.MPPulse(
        0.9896702283884652, 0.26748362633618167, 2.0261584733312343, 266.40049492842587
    )
    ts = np.linspace(0.0, float(pulse.end_time), 400001)
    peak = float(np.max(np.abs(np.asarray(pulse.acceleration(ts)))))
    assert 1.0 < peak / (G / 5.9) < 1.0003  # barely above the threshold
    up = jr.simulate(jr.Block(5.9, 1.0), jr.FixedBase(), pulse)
    assert int(up.outcome) == jr.Outcome.ROCKING
    assert abs(float(pulse.acceleration(up.uplift_time))) == pytest.approx(
        G / 5.9, rel=1e-9
    )
    calm = jr.simulate(jr.Block(G / peak * 0.9999, 1.0), jr.FixedBase(), pulse)
    assert int(calm.outcome) == jr.Outcome.NO_ROCKING
    bm = jr.behavior_map([5.8, 5.9, 6.0], [0.5, 1.0], jr.FixedBase(), pulse)
    np.testing.assert_array_equal(bm.outcome, [[0, 0], [1, 1], [1, 1]])


def test_phase_shift_mirrors_rotation():
    a, f, g, nu = 1.15, 0.68, 1.6, 30.0
    block, base = jr.Block(3.0, 0.5), jr.LinearIsolator(2.0, 0.35, 0.5)
    r1 = jr.simulate(block, base, jr.MPPulse(a, f, g, nu), history=True)
    r2 = jr.simulate(block, base, jr.MPPulse(a, f, g, nu + 180.0), history=True)
    assert int(r1.impacts) >= 2
    assert int(r1.impacts) == int(r2.impacts)
    assert float(r2.max_rotation) == pytest.approx(float(r1.max_rotation), rel=1e-9)
    assert float(r2.uplift_time) == pytest.approx(float(r1.uplift_time), abs=1e-10)
    np.testing.assert_allclose(
        r2.history.event_times, r1.history.event_times, atol=1e-9
    )
    i = np.argmax(np.abs(r1.history.theta))
    j = np.argmin(np.abs(r2.history.t - r1.history.t[i]))
    assert r2.history.theta[j] == pytest.approx(-r1.history.theta[i], rel=1e-6)


def test_stiff_light_isolator_approaches_fixed_base():
    """T_s = 0.02 s and a heavy base (mass ratio 0.01) behave as a fixed base."""
    block = jr.Block(5.0, 1.0)
    fixed = jr.simulate(block, jr.FixedBase(), PULSE)
    stiff = jr.simulate(block, jr.LinearIsolator(0.02, 0.35, 0.01), PULSE)
    soft = jr.simulate(block, jr.LinearIsolator(2.0, 0.35, 0.5), PULSE)
    assert int(stiff.outcome) == int(fixed.outcome)
    assert float(stiff.uplift_time) == pytest.approx(float(fixed.uplift_time), abs=2e-3)
    assert float(stiff.max_rotation) == pytest.approx(
        float(fixed.max_rotation), rel=2e-2
    )
    assert float(stiff.max_base_displacement) < 1e-3
    # ... whereas the paper's isolator does change the answer.
    assert abs(float(soft.uplift_time) - float(fixed.uplift_time)) > 1e-2


def test_history_ground_acceleration_is_the_pulse(fixed_rocking):
    """History's x_g'' (compiled, on padded times) is Eq. 3.1's derivative,
    written here in NumPy, at every recorded time."""
    h = fixed_rocking[1].history
    a, f, g, nu = 1.15, 0.68, 1.6, np.deg2rad(180.0)
    tau = h.t - g / (2 * f)
    w = 2 * np.pi * f
    want = -(a * np.pi * f / g) * (
        np.sin(w * tau / g) * np.cos(w * tau + nu)
        + g * np.sin(w * tau + nu) * (1 + np.cos(w * tau / g))
    )
    want = np.where(np.abs(tau) <= g / (2 * f), want, 0.0)
    assert h.ground_acceleration.shape == h.t.shape
    np.testing.assert_allclose(h.ground_acceleration, want, rtol=0, atol=1e-12)
    assert np.abs(want).max() > 1.0  # the pulse is in the window


def test_carlson_rf_matches_scipy():
    from scipy.special import elliprf

    from jaxrock._free import carlson_rf

    rng = np.random.default_rng(7)
    x, y, z = 10.0 ** rng.uniform(-16, 2, (3, 200))
    x[:20] = 0.0  # one argument may vanish
    ours = np.asarray(carlson_rf(x, y, z))
    np.testing.assert_allclose(ours, elliprf(x, y, z), rtol=1e-15)


@pytest.mark.parametrize(
    "lam, size, apex, to",
    [
        (3.0, 1.0, 0.5, 0.0),  # apex -> impact
        (7.0, 3.0, 0.999, 0.2),  # near the separatrix
        (1.0, 0.2, 1e-4, 0.0),  # a tiny rocking of a squat block
        (5.0, 1.0, 1 - 1e-5, 0.5),  # at the separatrix (a log singularity)
    ],
)
def test_free_rocking_time_from_apex_matches_an_ode(lam, size, apex, to):
    """The closed form of `_free.py` against SciPy's DOP853 at rtol 1e-13 on
    theta'' = -p^2 sin(alpha - theta), from rest at the apex."""
    from scipy.integrate import solve_ivp

    from jaxrock._free import time_from_apex

    block = jr.Block(lam, size)
    p, alpha = float(block.p), float(block.alpha)
    theta_a, theta = apex * alpha, to * apex * alpha
    k, x = math.sin((alpha - theta_a) / 2), math.sin((alpha - theta) / 2)

    def reached(t, y):
        return y[0] - theta

    reached.terminal = True
    sol = solve_ivp(
        lambda t, y: [y[1], -(p**2) * math.sin(alpha - y[0])],
        (0.0, 1e3),
        [theta_a, 0.0],
        events=reached,
        method="DOP853",
        rtol=1e-13,
        atol=1e-16,
    )
    expected = sol.t_events[0][0]
    assert float(time_from_apex(p, x, k, x - k)) == pytest.approx(expected, rel=1e-10)


def _bouc_wen_bases(A, gamma, beta, Y):
    """Every isolator with the closed-form z, of these Bouc-Wen constants."""
    bw = dict(yield_displacement=Y, A=A, gamma=gamma, beta=beta)
    return [
        jr.FrictionPendulum(0.11, 2.24, 0.5, **bw),
        jr.BilinearIsolator(0.06, 2.5, mass_ratio=0.5, **bw),
        jr.SphericalRollingIsolator(1.5, 0.005, 0.5, **bw),
        jr.ConicalRollingIsolator(0.1, 0.005, 0.5, apex=1e-3, **bw),
    ]


@pytest.mark.parametrize("kind", range(4), ids=["fps", "bilinear", "sphere", "cone"])
@pytest.mark.parametrize(
    "A, gamma, beta, Y",
    [(1.0, 0.9, 0.1, 5e-4), (1.2, 0.3, 0.7, 1e-3)],  # paper's; |z| shrinking like tanh
)
def test_bouc_wen_z_in_closed_form_equals_the_ode(A, gamma, beta, Y, kind):
    """eta = 2: z explicit in u along each monotone stretch, restarted at each
    reversal of u', against Bouc-Wen's ODE integrated along the same u(t); the
    force's loop F / M = restoring force + (Q / M) z with it."""
    base = _bouc_wen_bases(A, gamma, beta, Y)[kind]
    assert base.n_states == 5

    def u(t):  # reversals of uneven amplitude, some within a few Y
        return 0.004 * np.sin(2 * np.pi * t) + 0.0025 * np.sin(9.0 * t)

    def u_dot(t):
        return 0.008 * np.pi * np.cos(2 * np.pi * t) + 0.0225 * np.cos(9.0 * t)

    def z_dot(t, z):
        v = u_dot(t)
        return [(A * v - gamma * abs(v) * z[0] * abs(z[0]) - beta * v * z[0] ** 2) / Y]

    ts = np.linspace(0.0, 3.0, 601)
    ode = solve_ivp(z_dot, (0, 3), [0.0], t_eval=ts, rtol=1e-12, atol=1e-14).y[0]
    hysteretic = jax.jit(lambda s: base.hysteretic(s))
    force = jax.jit(lambda s: base.force(s))
    turn = jax.jit(lambda s: base.at_transition(s, jnp.asarray(True)))
    state = np.zeros(5)
    closed, forces, reversals = [], [], 0
    for a, b in zip(np.r_[ts[0], ts[:-1]], ts):
        if u_dot(a) * u_dot(b) < 0:  # a reversal: the memory restarts there
            r = brentq(u_dot, a, b, xtol=1e-15)
            state = np.array(turn(np.array([u(r), 0.0, *state[2:]])))
            reversals += 1
        state[:2] = u(b), u_dot(b)
        closed.append(float(hysteretic(jnp.asarray(state))))
        forces.append(float(force(jnp.asarray(state))))
    assert reversals >= 6
    assert np.max(np.abs(ode)) > 0.9  # z saturates, and comes back
    np.testing.assert_allclose(closed, ode, atol=1e-9)
    loop = np.asarray(base.restoring_force(u(ts))) + base.strength_per_mass * ode
    np.testing.assert_allclose(forces, loop, rtol=1e-9, atol=1e-8)  # z: 1e-9


@pytest.mark.parametrize(
    "base",
    [
        jr.LinearIsolator(period=2.0, damping=0.35, mass_ratio=0.5),
        jr.FrictionPendulum(friction=0.11, radius=2.24, mass_ratio=0.5),
        jr.IntegratedFrictionPendulum(friction=0.11, radius=2.24, mass_ratio=0.5),
    ],
)
def test_held_base_states_have_zero_rates(base):
    """The flat loop's steps carry the base states past `n_integrated` as they
    are: their rates must be zero in every state."""
    n = base.n_states if base.n_integrated is None else base.n_integrated
    rng = np.random.default_rng(0)
    for _ in range(20):
        state = jnp.asarray(
            rng.normal(size=base.n_states) * [0.1, 1.0, 0.1, 1.0, 3.0][: base.n_states]
        )
        rates = np.asarray(base.rates(state, jnp.asarray(rng.normal())))
        assert rates.shape == (base.n_states,)
        assert np.all(rates[n:] == 0.0)
        assert np.all(rates[:n] != 0.0)  # (u' and u'' of a random state)


def test_each_free_rocking_half_cycle_is_at_most_e_times_the_one_before():
    """The bound `_free._impacts_to_rest` rests on: the time from an apex to
    the impact, over the impact's speed, grows with the apex, so at the speed
    e v it is at most e times that at v; checked from tiny rocking to the
    separatrix."""
    from jaxrock._free import time_from_apex

    block = jr.Block(4.0, 1.0)
    p, alpha = float(block.p), float(block.alpha)
    x0 = math.sin(alpha / 2)
    apex = alpha * np.concatenate(
        [np.geomspace(1e-8, 0.5, 200), 1 - np.geomspace(0.5, 1e-9, 200)]
    )
    k = np.sin((alpha - apex) / 2)
    gap2 = x0**2 - k**2  # (theta' / 2p)^2 at the impact
    half = np.asarray(time_from_apex(p, x0, k, gap2 / (x0 + k)))
    per_speed = half / np.sqrt(gap2)
    assert np.all(np.diff(per_speed) >= -1e-12 * per_speed[1:])
    assert per_speed[-1] > 3 * per_speed[0]  # not a constant: the bound is used


@pytest.mark.parametrize("max_segments", [2000, 40])
def test_free_rocking_counts_a_chain_of_impacts_as_one_at_a_time(
    monkeypatch, max_segments
):
    """`free_rocking` counts the impacts down to rest at once where the whole
    chain falls inside the window (`_impacts_to_rest`); with the chain turned
    off it counts them one at a time. Random lanes, rising and falling, some
    close to the separatrix, windows that end anywhere in the chain (and a
    segment limit hit in it), give the same counts both ways."""
    from jaxrock import _free
    from jaxrock._dynamics import Phase
    from jaxrock._model import initial_carry
    from jaxrock._scene import prepare

    rng = np.random.default_rng(3)
    n = 400
    block = jr.Block(rng.uniform(2.0, 8.0, n), rng.uniform(0.3, 3.0, n))
    base = jr.FixedBase()
    opts = jr.SolverOptions(max_segments=max_segments)
    alpha, p = np.asarray(block.alpha), np.asarray(block.p)
    theta = rng.uniform(0.0, 0.9, n) * alpha
    # Below the separatrix: theta'^2 < 2 p^2 (1 - cos(alpha - theta)).
    room = 2 * p**2 * (1 - np.cos(alpha - theta))
    theta_dot = np.sqrt(rng.uniform(0.0, 1.0, n) * room) * rng.choice([-1, 1], n)
    sign = rng.choice([-1.0, 1.0], n)
    end = float(PULSE.end_time)
    duration = end + rng.uniform(0.0, 40.0, n)
    c = jax.vmap(lambda b: initial_carry(b, base, prepare(PULSE)))(block)
    c = eqx.tree_at(
        lambda c: (c.t, c.y, c.phase, c.sign),
        c,
        (
            jnp.full(n, end),
            (jnp.asarray(sign * theta), jnp.asarray(sign * theta_dot), None),
            jnp.where(theta_dot > 0, Phase.RISING, Phase.FALLING),
            jnp.asarray(sign),
        ),
    )
    ready = _free.free_rocking_ready(c, block, end)
    assert bool(jnp.all(ready))

    def finish():  # traced anew each time, so that it reads the patch
        run = eqx.filter_jit(lambda *a: _free.free_rocking(*a))
        return run(c, block, base, duration, opts, ready)

    chained = finish()
    monkeypatch.setattr(
        _free, "_impacts_to_rest", lambda *a: (jnp.int32(0), jnp.asarray(False))
    )
    one_at_a_time = finish()
    for field in ("impacts", "segments", "done", "max_theta"):
        np.testing.assert_array_equal(
            getattr(chained, field), getattr(one_at_a_time, field), err_msg=field
        )
    impacts = np.asarray(chained.impacts)
    assert np.sum(impacts == 0) < n // 4
    if max_segments == 2000:
        assert impacts.max() > 100
    else:
        assert np.sum(np.asarray(chained.segments) >= max_segments) > 10


@pytest.mark.parametrize(
    "pulse",
    [PULSE, jr.MPPulse(0.8, 1.3, 2.5, 40.0, t0=1.5), jr.SinePulse(3.0, 2.0)],
    ids=["san-fernando", "mp-late", "sine"],
)
def test_a_pulses_bounds_of_its_acceleration_hold_and_are_second_order(pulse):
    """`acceleration_bound` and `acceleration_lower_bound` of a pulse bound
    x_g'' (sampled densely) over intervals that start before, inside and
    after it and cross its ends; inside it they are second-order tight, piece
    by piece: within the curvature's (w / pieces)^2 / 2 of the true range."""
    from jaxrock._ground import PULSE_BOUND_PIECES

    rng = np.random.default_rng(5)
    start, end = float(pulse.start_time), float(pulse.end_time)
    curvature = float(pulse.acceleration_curvature)
    for w in (1e-3, 1e-2, 0.1, 0.5):
        for t0 in rng.uniform(start - 0.3, end + 0.1, 40):
            t = np.linspace(t0, t0 + w, 401)
            a = np.asarray(jax.vmap(pulse.acceleration)(jnp.asarray(t)))
            upper = float(pulse.acceleration_bound(t0, t0 + w))
            lower = float(pulse.acceleration_lower_bound(t0, t0 + w))
            assert upper >= np.abs(a).max() - 1e-12
            assert lower <= a.min() + 1e-12
            if start < t0 and t0 + w < end:
                slack = curvature * (w / PULSE_BOUND_PIECES) ** 2 / 2 + 1e-12
                assert upper <= np.abs(a).max() + 2 * slack
                assert lower >= a.min() - 2 * slack
