"""A compiled baseline of jaxrock's model, written by hand in Numba.

The peer that the benchmarks run beside jaxrock: the same model (docs/model.md)
written again from its equations, with nothing from jaxrock's engine. A block
on a fixed base, a linear isolator or a friction pendulum whose Bouc-Wen z is
integrated with the motion (any exponent eta), under a Mavroeidis &
Papageorgiou pulse or a record (samples linear between them, zero outside).

- Dormand-Prince 5(4) with its continuous extension of order 4 (Hairer's
  DOPRI5), the usual integral controller on the RMS norm of the error
  (safety 0.9, factors 0.2 to 10), FSAL.
- Steps never cross a sample of a record nor the end of the excitation (the
  steps to the next one are equal and no longer than the controller's
  proposal); while a pulse lasts they are at most 1 / (32 f_p) long.
- Events located on the dense output (Illinois regula falsi, to 1e-13 s):
  uplift, apex, impact, rising again before an impact, overturning, and on
  an isolated base the reversals of u' (peaks of |u|). Each phase's two
  conditions fire when they go from > 0 to <= 0 over a step; the earliest
  wins.
- The impact map, rest rule and uplift test of docs/model.md; the chatter
  window of the rest rule read from a record's samples, bounded by the
  pulse's largest rate of change for a pulse.
- Shortcuts that a careful hand-written code takes: a block at rest on a
  fixed base jumps to where |x_g''| next reaches g tan(alpha) (a record's
  samples, or a scan of the pulse on its step grid); once the ground is
  still, a block rocking on a fixed base on the near side of its corner
  below the overturning energy has its max rotation in closed form (its
  energy only falls), and a block at rest on an isolated base ends the
  analysis once the base's energy (a Lyapunov function of the linear
  isolator and of Bouc-Wen with gamma >= |beta|) bounds its force below
  the uplift level and |u| below max |u|.

Cells run in parallel with `numba.prange`, one analysis a cell, dealt in a
fixed random order so that threads carry equal work.

    import peer
    out = peer.behavior_map(lam, size, ("linear", 2.0, 0.35, 0.5),
                            peer.mp_pulse(1.15, 0.68, 1.6, 180.0))

Bases: ("fixed",), ("linear", T_s, xi, mbar) and
("fps", mu, R, mbar, Y, A, gamma, beta, eta), the tuples of tests/reference.py.
"""

import math
import time

import numba
import numpy as np
from numba import njit, prange

G = 9.81
FIXED, LINEAR, FPS = 0, 1, 2
PULSE, RECORD = 0, 1
TRANSLATION, RISING, FALLING = 0, 1, 2
NO_ROCKING, ROCKING, OVERTURNED = 0, 1, 2
SUCCESS, MAX_STEPS, STEP_TOO_SMALL = 0, 1, 2

# Dormand-Prince 5(4) (Hairer, Norsett & Wanner, DOPRI5).
C2, C3, C4, C5 = 1 / 5, 3 / 10, 4 / 5, 8 / 9
A21 = 1 / 5
A31, A32 = 3 / 40, 9 / 40
A41, A42, A43 = 44 / 45, -56 / 15, 32 / 9
A51, A52, A53, A54 = 19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729
A61, A62, A63, A64, A65 = (
    9017 / 3168,
    -355 / 33,
    46732 / 5247,
    49 / 176,
    -5103 / 18656,
)
A71, A73, A74, A75, A76 = 35 / 384, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84
E1, E3, E4, E5, E6, E7 = (
    71 / 57600,
    -71 / 16695,
    71 / 1920,
    -17253 / 339200,
    22 / 525,
    -1 / 40,
)
D1, D3, D4, D5, D6, D7 = (
    -12715105075 / 11282082432,
    87487479700 / 32700410799,
    -10690763975 / 1880347072,
    701980252875 / 199316789632,
    -1453857185 / 822651844,
    69997945 / 29380423,
)
LOCATE_TOL = 1e-13  # s: the bracket of a located event
MAX_STEPS_DEFAULT = 2_000_000


def mp_pulse(amplitude, frequency, gamma, phase_deg, t0=None):
    """The motion array of a Mavroeidis & Papageorgiou pulse: (kind, samples,
    parameters) with A (m/s), f_p (Hz), gamma, nu (degrees) and t0 (s, by
    default gamma / (2 f_p))."""
    if t0 is None:
        t0 = gamma / (2 * frequency)
    w = 2 * math.pi * frequency
    # |d x_g''/dt| <= (A pi f_p / gamma) w (1 / gamma + 2 + 2 gamma): each
    # factor of the two products bounded by its amplitude and rate.
    jerk = amplitude * math.pi * frequency / gamma * w * (1 / gamma + 2 + 2 * gamma)
    end = t0 + gamma / (2 * frequency)
    params = np.array(
        [amplitude, frequency, gamma, math.radians(phase_deg), t0, end]
        + [1 / (32 * frequency), jerk],
        dtype=np.float64,
    )
    return PULSE, np.zeros(2), params


def record(samples, dt):
    """The motion array of a record: x_g'' samples (m/s^2) every dt s."""
    a = np.ascontiguousarray(samples, dtype=np.float64)
    params = np.array([dt, 0, 0, 0, 0, (a.size - 1) * dt, math.inf, 0.0])
    return RECORD, a, params


def _base_params(base):
    """(kind, parameters): per unit of the total mass M, f = F / M is
    p[0] u + p[1] u' (linear) or p[0] u + p[1] z (friction pendulum);
    p[2] = mbar; the friction pendulum's p[3:8] = Y, A, gamma, beta, eta."""
    kind = base[0]
    p = np.zeros(8)
    if kind == "fixed":
        return FIXED, p
    if kind == "linear":
        _, period, xi, mbar = base
        w = 2 * math.pi / period
        p[:3] = w * w, 2 * xi * w, mbar
        return LINEAR, p
    if kind == "fps":
        _, mu, radius, mbar, Y, A, gam, bet, eta = base
        p[:] = G / radius, mu * G, mbar, Y, A, gam, bet, eta
        return FPS, p
    raise ValueError(f"unknown base {base!r}")


@njit(cache=True, inline="always")
def _ground(t, mkind, mp, samples):
    """x_g''(t) (m/s^2)."""
    if mkind == PULSE:
        amp, fp, gam, nu, t0 = mp[0], mp[1], mp[2], mp[3], mp[4]
        tau = t - t0
        if abs(tau) > gam / (2 * fp):
            return 0.0
        w = 2 * math.pi * fp
        return -(amp * math.pi * fp / gam) * (
            math.sin(w * tau / gam) * math.cos(w * tau + nu)
            + gam * math.sin(w * tau + nu) * (1 + math.cos(w * tau / gam))
        )
    n = samples.size
    x = t / mp[0]
    if t < 0 or x > n - 1:
        return 0.0
    k = min(int(x), n - 2)
    return samples[k] + (samples[k + 1] - samples[k]) * (x - k)


@njit(cache=True, inline="always")
def _force(y, bkind, bp):
    """F / M of the isolator."""
    if bkind == LINEAR:
        return bp[0] * y[2] + bp[1] * y[3]
    if bkind == FPS:
        return bp[0] * y[2] + bp[1] * y[4]
    return 0.0


@njit(cache=True)
def _rhs(t, y, s, out, geo, bkind, bp, mkind, mp, samples):
    """The vector field of (theta, theta', u, u', z); s = 0 in translation.

    Lagrange's equations with m = 1 (J = 4/3 r^2, M = 1 + 1 / mbar):
    M u'' + c1 theta'' + s1 theta'^2 + M f = -M x_g'',
    c1 u'' + J theta'' + g s1 = -c1 x_g''."""
    ag = _ground(t, mkind, mp, samples)
    alpha, b, h, r = geo[0], geo[1], geo[2], geo[3]
    if bkind == FIXED:
        out[2] = out[3] = out[4] = 0.0
        if s == 0:
            out[0] = out[1] = 0.0
        else:
            phi = s * alpha - y[0]
            out[0] = y[1]
            out[1] = -geo[4] * (math.sin(phi) + ag / G * math.cos(phi))
        return
    f = _force(y, bkind, bp)
    total = 1.0 + 1.0 / bp[2]
    if s == 0:
        out[0] = out[1] = 0.0
        out[2] = y[3]
        out[3] = -f - ag
    else:
        th, thd = y[0], y[1]
        ct, st = math.cos(th), math.sin(th)
        c1 = h * ct + s * b * st
        s1 = s * b * ct - h * st
        inertia = 4.0 / 3.0 * r * r
        r1 = -total * ag - s1 * thd * thd - total * f
        r2 = -c1 * ag - G * s1
        det = total * inertia - c1 * c1
        out[0] = thd
        out[1] = (total * r2 - c1 * r1) / det
        out[2] = y[3]
        out[3] = (inertia * r1 - c1 * r2) / det
    if bkind == FPS:
        ud, z = y[3], y[4]
        Y, A, gam, bet, eta = bp[3], bp[4], bp[5], bp[6], bp[7]
        az = abs(z)
        if eta == 2.0:
            zp1, zp = az, az * az
        else:
            zp1, zp = az ** (eta - 1), az**eta
        out[4] = (A * ud - gam * abs(ud) * z * zp1 - bet * ud * zp) / Y
    else:
        out[4] = 0.0


@njit(cache=True)
def _conditions(phase, s, t, y, fixed, thr, bkind, bp, mkind, mp, samples):
    """The phase's two event conditions (> 0 inside the phase)."""
    if phase == TRANSLATION:
        if fixed:
            a = _ground(t, mkind, mp, samples)
        else:
            a = -_force(y, bkind, bp)
        return a + thr, thr - a
    if phase == RISING:
        return math.pi / 2 - s * y[0], s * y[1]
    return s * y[0], -s * y[1]


@njit(cache=True)
def _dense_coefficients(y0, y1, K, h, n, rc):
    for i in range(n):
        d = y1[i] - y0[i]
        rc[0, i] = y0[i]
        rc[1, i] = d
        rc[2, i] = h * K[0, i] - d
        rc[3, i] = d - h * K[6, i] - rc[2, i]
        rc[4, i] = h * (
            D1 * K[0, i]
            + D3 * K[2, i]
            + D4 * K[3, i]
            + D5 * K[4, i]
            + D6 * K[5, i]
            + D7 * K[6, i]
        )


@njit(cache=True)
def _dense(theta, rc, n, out):
    """The continuous extension at theta in [0, 1] of the step."""
    t1 = 1.0 - theta
    for i in range(n):
        out[i] = rc[0, i] + theta * (
            rc[1, i] + t1 * (rc[2, i] + theta * (rc[3, i] + t1 * rc[4, i]))
        )


@njit(cache=True)
def _value(which, phase, s, t, y, fixed, thr, bkind, bp, mkind, mp, samples):
    """Condition `which` (0, 1) of the phase, or (2) u'."""
    if which == 2:
        return y[3]
    g1, g2 = _conditions(phase, s, t, y, fixed, thr, bkind, bp, mkind, mp, samples)
    return g1 if which == 0 else g2


@njit(cache=True)
def _locate(
    which, sign, lo, hi, glo, ghi, t0, h, rc, n, tmp, phase, s, fixed, thr,
    bkind, bp, mkind, mp, samples,
):  # fmt: skip
    """The root of sign * value(which) on the dense output between the
    fractions lo (value > 0) and hi (value <= 0) of the step: Illinois regula
    falsi until the bracket is below LOCATE_TOL s. Returns the fraction hi
    (the condition has fired there)."""
    side = 0
    for _ in range(200):
        if (hi - lo) * abs(h) <= LOCATE_TOL or ghi == 0.0:
            break
        x = hi - ghi * (hi - lo) / (ghi - glo)
        if not (lo < x < hi):
            x = 0.5 * (lo + hi)
        _dense(x, rc, n, tmp)
        gx = sign * _value(
            which, phase, s, t0 + x * h, tmp, fixed, thr, bkind, bp, mkind, mp, samples
        )
        if gx > 0:
            lo, glo = x, gx
            if side == 1:
                ghi *= 0.5
            side = 1
        else:
            hi, ghi = x, gx
            if side == -1:
                glo *= 0.5
            side = -1
    return hi


@njit(cache=True)
def _next_uplift_fixed(t, t_window, thr, mkind, mp, samples):
    """Where |x_g''| next reaches thr after t, for a block at rest on a fixed
    base: (time, s), s = 0 where it does not before the window's end."""
    if mkind == RECORD:
        dt = mp[0]
        n = samples.size
        k = int(t / dt)
        while k < n and k * dt <= t:
            k += 1
        while k > 0 and (k - 1) * dt > t:
            k -= 1
        while k < n and abs(samples[k]) < thr:
            k += 1
        if k >= n or k * dt > t_window:
            return t_window, 0
        lo = max((k - 1) * dt, t)
        a_lo = _ground(lo, mkind, mp, samples)
        a_hi = samples[k]
        level = thr if a_hi > 0 else -thr
        up = lo + (k * dt - lo) * (level - a_lo) / (a_hi - a_lo)
        return min(max(up, t), k * dt), (1 if level < 0 else -1)
    end = min(mp[5], t_window)
    step = mp[6]
    a0 = _ground(t, mkind, mp, samples)
    t0 = t
    while t0 < end:
        t1 = min(t0 + step, end)
        a1 = _ground(t1, mkind, mp, samples)
        if a1 <= -thr or a1 >= thr:
            sign = 1.0 if a1 <= -thr else -1.0  # root of thr + sign * a
            lo, hi = t0, t1
            glo, ghi = thr + sign * a0, thr + sign * a1
            side = 0
            for _ in range(200):
                if hi - lo <= LOCATE_TOL or ghi == 0.0:
                    break
                x = hi - ghi * (hi - lo) / (ghi - glo)
                if not (lo < x < hi):
                    x = 0.5 * (lo + hi)
                gx = thr + sign * _ground(x, mkind, mp, samples)
                if gx > 0:
                    lo, glo = x, gx
                    if side == 1:
                        ghi *= 0.5
                    side = 1
                else:
                    hi, ghi = x, gx
                    if side == -1:
                        glo *= 0.5
                    side = -1
            return hi, (1 if sign > 0 else -1)
        t0, a0 = t1, a1
    return t_window, 0


@njit(cache=True)
def _next_break(t, t_window, mkind, mp, samples):
    """The end of the step after t: the next sample of a record, the end of
    the excitation, or the window's end."""
    end = mp[5]
    if mkind == RECORD and t < end:
        dt = mp[0]
        k = int(t / dt) + 1
        while k * dt <= t:
            k += 1
        while (k - 1) * dt > t:
            k -= 1
        return min(k * dt, end, t_window)
    if t < end:
        return min(end, t_window)
    return t_window


@njit(cache=True)
def _quiet(y, thr, max_u, bkind, bp):
    """At rest on an isolated base with the ground still: whether the base's
    energy V (non-increasing) bounds |F| / M below thr and |u| by max |u|."""
    kk = bp[0]
    if bkind == LINEAR:
        v2 = kk * y[2] * y[2] + y[3] * y[3]  # 2 V / M
        umax = math.sqrt(v2 / kk)
        fmax = kk * umax + bp[1] * math.sqrt(v2)
    else:
        Y, A, gam, bet, eta = bp[3], bp[4], bp[5], bp[6], bp[7]
        if gam < abs(bet) or bp[1] <= 0:
            return False
        # V = K u^2 / 2 + M u'^2 / 2 + Q Y z^2 / (2 A): dV/dt = -(Q / A) |u'|
        # |z|^eta (gamma |z| + beta sgn(u' z) |z|) <= 0 with the ground still.
        v2 = kk * y[2] * y[2] + y[3] * y[3] + bp[1] * Y * y[4] * y[4] / A
        umax = math.sqrt(v2 / kk)
        zmax = min((A / (gam + bet)) ** (1 / eta), math.sqrt(v2 * A / (bp[1] * Y)))
        if abs(y[4]) > (A / (gam + bet)) ** (1 / eta):
            return False
        fmax = kk * umax + bp[1] * zmax
    return fmax < thr and umax <= max_u


@njit(cache=True)
def analysis(
    lam, size, bkind, bp, mkind, mp, samples, duration, rtol, atol, rest_tol,
    free_tail, max_steps,
):  # fmt: skip
    """One analysis. Returns (outcome, max |theta| / alpha, max |u|, impacts,
    uplift time, accepted steps, rejected steps, status)."""
    alpha = math.atan(1.0 / lam)
    b, h = size * math.sin(alpha), size * math.cos(alpha)
    p2 = 3 * G / (4 * size)
    geo = np.array([alpha, b, h, size, p2])
    fixed = bkind == FIXED
    n = 2 if fixed else (4 if bkind == LINEAR else 5)
    thr = G * b / h
    if fixed:
        e = 1 - 1.5 * math.sin(alpha) ** 2
        den = 1.0
        total = math.inf
    else:
        mb = 1.0 / bp[2]
        total = 1.0 + mb
        den = 4 * mb * h * h + 4 * mb * b * b + h * h + 4 * b * b
        e = (4 * mb * h * h - 2 * mb * b * b + h * h - 2 * b * b) / den
    t_exc = mp[5]
    hmax_shaking = mp[6]
    jerk = mp[7]
    t_window = duration

    y = np.zeros(5)
    y1 = np.zeros(5)
    ys = np.zeros(5)
    tmp = np.zeros(5)
    yev = np.zeros(5)
    K = np.zeros((7, 5))
    rc = np.zeros((5, 5))
    t = 0.0
    phase, s = TRANSLATION, 1
    rocked = False
    overturned = False
    uplift_time = math.nan
    max_th = 0.0
    max_u = 0.0
    impacts = 0
    accepted = 0
    rejected = 0
    status = SUCCESS
    hstep = min(1e-3, hmax_shaking)

    a0 = _ground(0.0, mkind, mp, samples)
    if a0 <= -thr:
        phase, s, rocked, uplift_time = RISING, 1, True, 0.0
    elif a0 >= thr:
        phase, s, rocked, uplift_time = RISING, -1, True, 0.0
    fresh = True  # K[0] and the start conditions need computing
    g1s = g2s = 0.0
    while t < t_window:
        if fixed and phase == TRANSLATION:
            t_up, s_up = _next_uplift_fixed(t, t_window, thr, mkind, mp, samples)
            if s_up == 0:
                break
            t = t_up
            phase, s = RISING, s_up
            y[0] = y[1] = 0.0
            if not rocked:
                rocked, uplift_time = True, t
            fresh = True
            continue
        if t >= t_exc:
            if fixed and free_tail and abs(y[0]) < alpha:
                # Free rocking: energy per unit mass, lost only at impacts.
                energy = 2.0 / 3.0 * size * size * y[1] * y[1] + G * size * (
                    math.cos(alpha - abs(y[0])) - math.cos(alpha)
                )
                if energy < G * size * (1 - math.cos(alpha)):
                    if phase == RISING:
                        c = math.cos(alpha) + energy / (G * size)
                        max_th = max(max_th, alpha - math.acos(min(c, 1.0)))
                    break
            if not fixed and phase == TRANSLATION and _quiet(y, thr, max_u, bkind, bp):
                break
        if fresh:
            se = 0 if phase == TRANSLATION else s
            _rhs(t, y, se, K[0], geo, bkind, bp, mkind, mp, samples)
            g1s, g2s = _conditions(
                phase, s, t, y, fixed, thr, bkind, bp, mkind, mp, samples
            )
            fresh = False
        se = 0 if phase == TRANSLATION else s
        # The step: equal steps to the next break, none longer than proposed.
        t_stop = _next_break(t, t_window, mkind, mp, samples)
        proposal = hstep
        if t < t_exc:
            proposal = min(proposal, hmax_shaking)
        parts = math.ceil((t_stop - t) / proposal * (1 - 1e-12))
        if parts <= 1:
            dt_step = t_stop - t
            t_new = t_stop
        else:
            dt_step = (t_stop - t) / parts
            t_new = t + dt_step
        if dt_step <= 1e-14 * (1.0 + abs(t)):
            status = STEP_TOO_SMALL
            break
        if accepted + rejected >= max_steps:
            status = MAX_STEPS
            break
        hh = dt_step
        for i in range(n):
            ys[i] = y[i] + hh * A21 * K[0, i]
        _rhs(t + C2 * hh, ys, se, K[1], geo, bkind, bp, mkind, mp, samples)
        for i in range(n):
            ys[i] = y[i] + hh * (A31 * K[0, i] + A32 * K[1, i])
        _rhs(t + C3 * hh, ys, se, K[2], geo, bkind, bp, mkind, mp, samples)
        for i in range(n):
            ys[i] = y[i] + hh * (A41 * K[0, i] + A42 * K[1, i] + A43 * K[2, i])
        _rhs(t + C4 * hh, ys, se, K[3], geo, bkind, bp, mkind, mp, samples)
        for i in range(n):
            ys[i] = y[i] + hh * (
                A51 * K[0, i] + A52 * K[1, i] + A53 * K[2, i] + A54 * K[3, i]
            )
        _rhs(t + C5 * hh, ys, se, K[4], geo, bkind, bp, mkind, mp, samples)
        for i in range(n):
            ys[i] = y[i] + hh * (
                A61 * K[0, i]
                + A62 * K[1, i]
                + A63 * K[2, i]
                + A64 * K[3, i]
                + A65 * K[4, i]
            )
        _rhs(
            t_new if parts <= 1 else t + hh,
            ys,
            se,
            K[5],
            geo,
            bkind,
            bp,
            mkind,
            mp,
            samples,
        )
        for i in range(n):
            y1[i] = y[i] + hh * (
                A71 * K[0, i]
                + A73 * K[2, i]
                + A74 * K[3, i]
                + A75 * K[4, i]
                + A76 * K[5, i]
            )
        for i in range(n, 5):
            y1[i] = y[i]
        _rhs(t_new, y1, se, K[6], geo, bkind, bp, mkind, mp, samples)
        err = 0.0
        for i in range(n):
            ei = hh * (
                E1 * K[0, i]
                + E3 * K[2, i]
                + E4 * K[3, i]
                + E5 * K[4, i]
                + E6 * K[5, i]
                + E7 * K[6, i]
            )
            sc = atol + rtol * max(abs(y[i]), abs(y1[i]))
            err += (ei / sc) ** 2
        err = math.sqrt(err / n)
        if err > 1.0:
            rejected += 1
            hstep = hh * max(0.2, 0.9 * err**-0.2)
            continue
        accepted += 1
        factor = 10.0 if err == 0.0 else min(10.0, max(0.2, 0.9 * err**-0.2))
        grown = hh * factor
        hstep = max(grown, proposal) if hh < proposal else grown
        g1e, g2e = _conditions(
            phase, s, t_new, y1, fixed, thr, bkind, bp, mkind, mp, samples
        )
        fire1 = g1s > 0 and g1e <= 0
        fire2 = g2s > 0 and g2e <= 0
        if not (fire1 or fire2):
            if not fixed and y[3] * y1[3] < 0:
                _dense_coefficients(y, y1, K, hh, n, rc)
                sign = 1.0 if y[3] > 0 else -1.0
                x = _locate(2, sign, 0.0, 1.0, sign * y[3], sign * y1[3], t, hh,
                            rc, n, tmp, phase, s, fixed, thr, bkind, bp, mkind,
                            mp, samples)  # fmt: skip
                _dense(x, rc, n, tmp)
                max_u = max(max_u, abs(tmp[2]))
            t = t_new
            for i in range(5):
                y[i] = y1[i]
                K[0, i] = K[6, i]
            max_th = max(max_th, abs(y[0]))
            max_u = max(max_u, abs(y[2]))
            g1s, g2s = g1e, g2e
            continue
        # An event: the earliest located root of the fired conditions.
        _dense_coefficients(y, y1, K, hh, n, rc)
        x1 = x2 = 2.0
        if fire1:
            x1 = _locate(0, 1.0, 0.0, 1.0, g1s, g1e, t, hh, rc, n, tmp, phase, s,
                         fixed, thr, bkind, bp, mkind, mp, samples)  # fmt: skip
        if fire2:
            x2 = _locate(1, 1.0, 0.0, 1.0, g2s, g2e, t, hh, rc, n, tmp, phase, s,
                         fixed, thr, bkind, bp, mkind, mp, samples)  # fmt: skip
        first = 0 if x1 <= x2 else 1
        x = min(x1, x2)
        _dense(x, rc, n, yev)
        for i in range(n, 5):
            yev[i] = y[i]
        if not fixed and y[3] * yev[3] < 0:
            sign = 1.0 if y[3] > 0 else -1.0
            xp = _locate(2, sign, 0.0, x, sign * y[3], sign * yev[3], t, hh, rc, n,
                         tmp, phase, s, fixed, thr, bkind, bp, mkind, mp,
                         samples)  # fmt: skip
            _dense(xp, rc, n, tmp)
            max_u = max(max_u, abs(tmp[2]))
        t = t + x * hh if x < 1.0 else t_new
        for i in range(5):
            y[i] = yev[i]
        max_u = max(max_u, abs(y[2]))
        max_th = max(max_th, abs(y[0]))
        fresh = True
        if phase == TRANSLATION:
            phase, s = RISING, (1 if first == 0 else -1)
            if not rocked:
                rocked, uplift_time = True, t
        elif phase == RISING and first == 0:
            overturned = True
            max_th = math.pi / 2
            break
        elif phase == RISING and s * y[0] > 0:
            phase = FALLING
        elif phase == RISING:
            # An apex at or below theta = 0: a rebound too small to lift the
            # block at all; it rests.
            y[0] = y[1] = 0.0
            phase = TRANSLATION
            a = _ground(t, mkind, mp, samples) if fixed else -_force(y, bkind, bp)
            if a <= -thr:
                phase, s = RISING, 1
            elif a >= thr:
                phase, s = RISING, -1
        elif first == 1:
            phase = RISING
        else:
            impacts += 1
            thd = y[1]
            ud = y[3]
            rise = (e * thd) ** 2 / (2 * p2 * math.sin(alpha))
            rest = e <= 0
            if not rest and rise < rest_tol * alpha:
                # The chatter that the rule cuts short ends within `window`
                # if the base's |acceleration| stays below `level` meanwhile.
                a_now = (
                    _ground(t, mkind, mp, samples) if fixed else -_force(y, bkind, bp)
                )
                level = 0.5 * (thr + abs(a_now))
                decel = p2 * math.cos(alpha) * (thr - level) / G
                if decel > 0 and e < 1:
                    if not fixed:
                        rest = True
                    else:
                        window = 2 * e * abs(thd) / (decel * (1 - e))
                        end = t + window
                        if mkind == RECORD:
                            peak = max(
                                abs(a_now), abs(_ground(end, mkind, mp, samples))
                            )
                            dt = mp[0]
                            k = int(t / dt) + 1
                            while k * dt < end and k < samples.size:
                                if k * dt > t:
                                    peak = max(peak, abs(samples[k]))
                                k += 1
                        else:
                            peak = abs(a_now) + jerk * window
                        rest = peak < level
            y[0] = 0.0
            if rest:
                y[1] = 0.0
                if not fixed:
                    y[3] = ud + h * thd / total
                phase = TRANSLATION
                a = _ground(t, mkind, mp, samples) if fixed else -_force(y, bkind, bp)
                if a <= -thr:
                    phase, s = RISING, 1
                elif a >= thr:
                    phase, s = RISING, -1
            else:
                y[1] = e * thd
                if not fixed:
                    y[3] = ud + 6 * h * b * b * thd / den
                phase, s = RISING, -s
            max_u = max(max_u, abs(y[2]))
    outcome = OVERTURNED if overturned else (ROCKING if rocked else NO_ROCKING)
    return (
        outcome,
        max_th / alpha,
        max_u,
        impacts,
        uplift_time,
        accepted,
        rejected,
        status,
    )


@njit(cache=True, parallel=True)
def _map(
    lams, sizes, order, bkind, bp, mkind, mp, samples, duration, rtol, atol,
    rest_tol, free_tail, max_steps,
):  # fmt: skip
    cells = order.size
    outcome = np.zeros(cells, np.int64)
    rotation = np.zeros(cells)
    base = np.zeros(cells)
    impacts = np.zeros(cells, np.int64)
    uplift = np.zeros(cells)
    accepted = np.zeros(cells, np.int64)
    rejected = np.zeros(cells, np.int64)
    status = np.zeros(cells, np.int64)
    for j in prange(cells):
        c = order[j]
        o = analysis(lams[c], sizes[c], bkind, bp, mkind, mp, samples, duration,
                     rtol, atol, rest_tol, free_tail, max_steps)  # fmt: skip
        outcome[c], rotation[c], base[c], impacts[c] = o[0], o[1], o[2], o[3]
        uplift[c], accepted[c], rejected[c], status[c] = o[4], o[5], o[6], o[7]
    return outcome, rotation, base, impacts, uplift, accepted, rejected, status


FIELDS = (
    "outcome",
    "max_rotation",
    "max_base_displacement",
    "impacts",
    "uplift_time",
    "steps",
    "rejected_steps",
    "status",
)


def behavior_map(
    slenderness,
    size,
    base,
    motion,
    *,
    rtol=1e-8,
    atol=1e-10,
    rest_tolerance=1e-6,
    duration=None,
    free_tail=True,
    threads=None,
    max_steps=MAX_STEPS_DEFAULT,
):
    """A behavior map over the grid slenderness x size: a dict of arrays of
    shape (len(slenderness), len(size)) (FIELDS), with `seconds` (the
    compiled call) and `threads`. `motion` is `mp_pulse(...)` or
    `record(...)`; `duration` defaults to the excitation's end plus 5 s."""
    lam = np.asarray(slenderness, dtype=np.float64)
    r = np.asarray(size, dtype=np.float64)
    lams, sizes = (
        np.ascontiguousarray(x.ravel()) for x in np.meshgrid(lam, r, indexing="ij")
    )
    bkind, bp = _base_params(base)
    mkind, samples, mp = motion
    if duration is None:
        duration = mp[5] + 5.0
    order = np.random.default_rng(0).permutation(lams.size)
    if threads is not None:
        numba.set_num_threads(threads)
    t = time.perf_counter()
    out = _map(lams, sizes, order, bkind, bp, mkind, mp, samples, float(duration),
               rtol, atol, rest_tolerance, free_tail, max_steps)  # fmt: skip
    seconds = time.perf_counter() - t
    shape = (lam.size, r.size)
    result = {k: v.reshape(shape) for k, v in zip(FIELDS, out)}
    result["seconds"] = seconds
    result["threads"] = numba.get_num_threads()
    return result


def simulate(slenderness, size, base, motion, **kwargs):
    """One analysis: a dict of FIELDS (numbers)."""
    out = behavior_map([slenderness], [size], base, motion, **kwargs)
    return {k: out[k][0, 0].item() for k in FIELDS}
