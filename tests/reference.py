"""An independent SciPy reference for one analysis (NumPy only, no jaxrock code).

Written from the equations of docs/model.md with explicit masses (m = 1,
m_b = m / mbar) and `numpy.linalg.solve` on the 2x2 mass matrix, so that an
algebra slip in jaxrock's reduced (per unit mass) equations would show.
`solve_ivp` with DOP853 at rtol 1e-10 / atol 1e-12, terminal events and a
restart loop (also at every kink of a record's x_g'', `breaks`); peaks of |u|
as non-terminal events at u' = 0.
"""

import math

import numpy as np
from scipy.integrate import solve_ivp

G = 9.81


def mp_pulse(amplitude, frequency, gamma, phase_deg, t0=None):
    """x_g''(t) of the Mavroeidis-Papageorgiou pulse, and its end time."""
    if t0 is None:
        t0 = gamma / (2 * frequency)
    nu = math.radians(phase_deg)
    half = gamma / (2 * frequency)

    def acc(t):
        tau = t - t0
        if abs(tau) > half:
            return 0.0
        w = 2 * math.pi * frequency
        return -(amplitude * math.pi * frequency / gamma) * (
            math.sin(w * tau / gamma) * math.cos(w * tau + nu)
            + gamma * math.sin(w * tau + nu) * (1 + math.cos(w * tau / gamma))
        )

    return acc, t0 + half, 1 / (32 * frequency)


def _next_break(breaks, t, t_end):
    """The first kink after t (with a margin of rounding), else t_end."""
    k = np.searchsorted(breaks, t * (1 + 1e-14) + 1e-14, side="right")
    return min(float(breaks[k]), t_end) if k < breaks.size else t_end


def record(samples, dt):
    """x_g''(t) of a recorded accelerogram (linear between samples, zero
    outside the record), its end time and its kinks (the sample times)."""
    a = [float(v) for v in samples]
    n = len(a)
    end = (n - 1) * dt

    def acc(t):
        if t < 0 or t > end:
            return 0.0
        k = min(int(t / dt), n - 2)
        frac = t / dt - k
        return a[k] + (a[k + 1] - a[k]) * frac

    return acc, end, np.arange(n) * dt


def simulate(
    slenderness,
    size,
    base,
    acc,
    t_end,
    max_step,
    *,
    rest_tolerance=1e-6,
    rtol=1e-10,
    atol=1e-12,
    breaks=None,
    restitution_factor=1.0,
    restitution=None,
    friction_samples=0,
    vertical=None,
    stop=None,
):
    """base: ("fixed",), ("linear", T, xi, mbar), ("fps", mu, R, mbar, Y, A, g, b, eta),
    ("bilinear", q, T, mbar, Y, A, g, b, eta): K = M (2 pi / T)^2, Q = q M g,
    ("cone", mu_r, (s, d), mbar, Y, A, g, b, eta): a rounded cone's M g s u /
    sqrt(u^2 + d^2) + mu_r M g z.

    The coefficient applied at a re-uplift is `restitution` if given, else
    `restitution_factor` times the momentum model's e (Eq. 2.13); the base's
    velocity then follows from the horizontal momentum M u' + m h theta' of
    block and base, conserved through the impact.

    With `friction_samples` > 0 it also returns `friction_needed`: the
    largest |R_x| / R_y of the base's force R on the block (inf where
    R_y <= 0), R = m (acceleration of the centre of mass, plus g upwards),
    over the analysis while the block has not passed its corner's vertical
    (s theta < alpha), read at every step's end and at `friction_samples`
    points inside each step (dense output), and at each impact the ratio
    |P_x| / P_y of the impulse: the change of the centre of mass's momentum
    (an impact after which rocking ends, its first rebound's e theta'-).

    `vertical(t)` is the ground's vertical acceleration a_v (m/s^2, upward):
    the block then feels g_eff = g + a_v(t) in its equation of rotation (the
    support's vertical acceleration acts as a change of gravity), in the
    uplift level g_eff b / h, in a pendulum's or a cone's normal force (K and
    Q times g_eff / g; the linear and bilinear isolators' are unchanged) and
    in the rest rule (its rebound at g_eff, and the level of the base's
    uplift at the least g_eff over twice the chatter's time at g_eff, on a
    fine grid). Where g_eff reaches 0 the analysis stops with `flight` True
    (the block would leave its base).

    `stop` = (D, T, zeta): past |u| = D the base compresses a stop, a spring
    and a dashpot of period T (s) and damping ratio zeta per unit total
    mass, which pushes it back with M (w^2 d + 2 zeta w d') (d = |u| - D,
    w = 2 pi / T) and never pulls; the solves stop wherever that push starts
    or ends (its force's kinks): at |u| = D, and, with damping, where
    w^2 d + 2 zeta w d' reaches 0 while |u| > D.

    Returns dict(outcome, max_rotation, max_base_displacement, impacts, uplift_time,
    impact_log, evaluations) with impact_log entries (theta_dot-, theta_dot+,
    u_dot-, u_dot+) and evaluations the vector field's (SciPy's nfev).
    """
    alpha = math.atan(1 / slenderness)
    b, h = size * math.sin(alpha), size * math.cos(alpha)
    m = 1.0
    kind = base[0]
    fixed = kind == "fixed"
    mb = math.inf if fixed else m / base[-1] if kind == "linear" else m / base[3]
    M = m + (0 if fixed else mb)
    inertia = m * size**2 / 3
    J = m * size**2 + inertia
    p2 = 3 * G / (4 * size)

    def gravity(t):
        return G if vertical is None else G + vertical(t)

    def isolator_force(x, t=None):
        """The force at t (the normal force of a pendulum or cone at g_eff)."""
        weight = 1.0 if t is None else gravity(t) / G
        u, ud = x[2], x[3]
        if kind == "linear":
            T, xi = base[1], base[2]
            w = 2 * math.pi / T
            return M * w * w * u + 2 * xi * M * w * ud
        if kind == "bilinear":
            q, T = base[1], base[2]
            return M * (2 * math.pi / T) ** 2 * u + q * M * G * x[4]
        if kind == "cone":  # height s sqrt(u^2 + d^2): force M g dh/du
            mu, (s, d) = base[1], base[2]
            force = M * G * s * u / math.sqrt(u * u + d * d) + mu * M * G * x[4]
            return weight * force
        mu, R = base[1], base[2]
        return weight * (M * G / R * u + mu * M * G * x[4])

    def stop_force(x, entering=False):
        """The stop's force; `entering`: just past the touch where the base
        meets it (d -> 0+: the dashpot's force at once). A base at a located
        touch (d = 0 to rounding, 1e-12 of the gap) moving out is entering."""
        if stop is None:
            return 0.0
        gap, period, zeta = stop
        u, ud = x[2], x[3]
        d = abs(u) - gap
        entering = entering or (u * ud > 0 and d > -1e-12 * gap)
        if entering:
            d = max(d, 0.0)
        elif d <= 0:
            return 0.0
        w = 2 * math.pi / period
        push = w * w * d + 2 * zeta * w * math.copysign(1.0, u) * ud
        return math.copysign(M * max(push, 0.0), u)

    def stop_margin(x):
        """min(d, push / w^2) (m): > 0 where the stop pushes the base."""
        gap, period, zeta = stop
        w = 2 * math.pi / period
        d = abs(x[2]) - gap
        return min(d, d + 2 * zeta / w * math.copysign(1.0, x[2]) * x[3])

    def stop_margin_rate(t, x, s):
        """The rate of `stop_margin` at one of its roots: d' where d is the
        smaller, else d' + 2 zeta d'' / w (the push's, over w^2)."""
        gap, period, zeta = stop
        w = 2 * math.pi / period
        sign = math.copysign(1.0, x[2])
        d, d_dot = abs(x[2]) - gap, sign * x[3]
        if d <= d + 2 * zeta / w * d_dot:
            return d_dot
        return d_dot + 2 * zeta / w * sign * rhs(t, x, s)[3]

    def bouc_wen(x):
        Y, A, gam, bet, eta = base[4:]
        ud, z = x[3], x[4]
        return (
            A * ud - gam * abs(ud) * z * abs(z) ** (eta - 1) - bet * ud * abs(z) ** eta
        ) / Y

    def rhs(t, x, s):
        if not all(map(math.isfinite, x)):  # a trial step that overflowed:
            return [math.nan] * len(x)  # rejected (math.cos(inf) would raise)
        ag, g = acc(t), gravity(t)
        th, thd = x[0], x[1]
        if fixed:
            if s == 0:
                return [0.0, 0.0]
            return [
                thd,
                -p2
                / G
                * (g * math.sin(s * alpha - th) + ag * math.cos(s * alpha - th)),
            ]
        F = isolator_force(x, t) + stop_force(x)
        if s == 0:
            udd = -F / M - ag
            out = [0.0, 0.0, x[3], udd]
        else:
            c1 = h * math.cos(th) + s * b * math.sin(th)
            s1 = s * b * math.cos(th) - h * math.sin(th)
            mass = np.array([[M, m * c1], [m * c1, J]])
            force = np.array([-M * ag - m * s1 * thd**2 - F, -m * c1 * ag - m * g * s1])
            udd, thdd = np.linalg.solve(mass, force)
            out = [thd, thdd, x[3], udd]
        if kind in ("fps", "bilinear", "cone"):
            out.append(bouc_wen(x))
        return out

    def abs_base_acc(t, x, entering=False):
        if fixed:
            return acc(t)
        return -(isolator_force(x, t) + stop_force(x, entering)) / M

    def thr_at(t):
        return gravity(t) * b / h

    def centre(th, s):
        """The centre of mass relative to the pivot (x = s b, y = 0), and its
        derivatives in theta: the block turned by -theta about the pivot."""
        x = -s * b * math.cos(th) + h * math.sin(th)
        y = s * b * math.sin(th) + h * math.cos(th)
        return x, y, y, -x  # X, Y, dX/dtheta, dY/dtheta

    def force_ratio(t, x, s):
        """|R_x| / R_y of the base's force on the block at (t, x)."""
        if s == 0:
            return abs(abs_base_acc(t, x)) / gravity(t)
        th, thd = x[0], x[1]
        if s * th >= alpha:
            return 0.0
        rates = rhs(t, x, s)
        thdd = rates[1]
        a_base = acc(t) if fixed else rates[3] + acc(t)
        X, Y, dX, dY = centre(th, s)
        # d2X/dtheta2 = -X, d2Y/dtheta2 = -Y (a rotation).
        r_x = m * (a_base + dX * thdd - X * thd**2)
        r_y = m * (gravity(t) + dY * thdd - Y * thd**2)
        return math.inf if r_y <= 0 else abs(r_x) / r_y

    def impulse_ratio(s, thd_minus, thd_plus, ud_minus, ud_plus):
        """|P_x| / P_y at an impact from the corner s to -s."""
        _, _, dx0, dy0 = centre(0.0, s)
        _, _, dx1, dy1 = centre(0.0, -s)
        p_x = m * ((ud_plus + dx1 * thd_plus) - (ud_minus + dx0 * thd_minus))
        p_y = m * (dy1 * thd_plus - dy0 * thd_minus)
        return abs(p_x) / p_y

    needed = 0.0

    n = 2 if fixed else (4 if kind == "linear" else 5)
    x = np.zeros(n)
    t = 0.0
    phase, s = "T", 1
    rocked = overturned = flight = False
    last_touch = [-math.inf, 0.0]  # the last touch of the stop, and its side
    uplift_time = math.nan
    max_th = max_u = 0.0
    impacts = 0
    evaluations = 0  # of the vector field (SciPy's nfev), a measure of work
    log = []
    thr = G * b / h
    if fixed:
        e = 1 - 1.5 * math.sin(alpha) ** 2
    else:
        den = 4 * mb * h * h + 4 * mb * b * b + m * h * h + 4 * m * b * b
        num = 4 * mb * h * h - 2 * mb * b * b + m * h * h - 2 * m * b * b
        e = num / den
    if restitution is not None:
        e = restitution
    elif restitution_factor != 1.0:
        e = restitution_factor * e

    def uplift_now(t, x, entering=False):
        a = abs_base_acc(t, x, entering)
        if a <= -thr_at(t):
            return 1
        if a >= thr_at(t):
            return -1
        return 0

    def chatter_ends(t, x, thd):
        """Whether the impacts that follow one of rebound e thd end before the
        base could lift the block: with L0 the base's acceleration now and
        level = (thr + L0) / 2, the flights decelerate at least
        p2 cos(alpha) (thr - level) / G while |base acceleration| < level, and
        end within S = 2 e |thd| / (decel (1 - e)); the base's acceleration
        must stay below `level` for S (a fixed base: x_g'' on a fine grid and
        at the kinks; an isolator: its acceleration now)."""
        a0 = abs(abs_base_acc(t, x))

        def chatter(low):
            level = 0.5 * (low + a0)
            decel = p2 * math.cos(alpha) * (low - level) / G
            if decel <= 0 or e >= 1:
                return level, None
            return level, 2 * e * abs(thd) / (decel * (1 - e))

        level, window = chatter(thr_at(t))  # S at g_eff of the impact
        if vertical is not None and window is not None:
            horizon = 2 * window
            grid = np.linspace(t, t + horizon, 65)
            least = min(gravity(tt) for tt in grid)
            level, window = chatter(least * b / h)
            if window is not None and window > horizon:
                return False
        if window is None:
            return False
        if not fixed:
            return True
        times = np.linspace(t, t + window, 65)
        inside = breaks[(breaks > t) & (breaks < t + window)]
        times = np.concatenate([times, inside])
        return max(abs(acc(tt)) for tt in times) < level

    s0 = uplift_now(t, x)
    if s0:
        phase, s, rocked, uplift_time = "R", s0, True, 0.0
    # Kinks of x_g'' (a record's sample times): no step crosses one, so each
    # solve ends at the next (DOP853's error estimate does not see a kink).
    breaks = np.asarray([] if breaks is None else breaks, dtype=float)
    for _ in range(10**6):
        if t >= t_end:
            break
        if fixed and phase == "T" and breaks.size and vertical is None:
            # At rest on a fixed base nothing moves until |x_g''| reaches thr;
            # x_g'' is linear between kinks: the crossing, from the samples.
            k = np.searchsorted(breaks, t, side="right")
            while k < breaks.size and abs(acc(breaks[k])) < thr:
                k += 1
            if friction_samples:  # |x_g''| at rest: linear between kinks
                crosses = k < breaks.size and breaks[k] <= t_end
                end = breaks[k] if crosses else t_end
                inside = breaks[(breaks > t) & (breaks < end)]
                levels = [abs(acc(tt)) for tt in [t, *inside]]
                levels.append(thr if crosses else abs(acc(t_end)))
                needed = max(needed, max(levels) / G)
            if k == breaks.size or breaks[k] > t_end:
                t = t_end
                break
            lo, a_lo = max(breaks[k - 1], t), acc(max(breaks[k - 1], t))
            a_hi = acc(breaks[k])
            level = thr if a_hi > 0 else -thr
            t = lo + (breaks[k] - lo) * (level - a_lo) / (a_hi - a_lo)
            phase, s, rocked = "R", 1 if level < 0 else -1, True
            uplift_time = t if math.isnan(uplift_time) else uplift_time
            continue
        if phase == "T":
            ev1 = lambda t, x, s: abs_base_acc(t, x) + thr_at(t)  # noqa: E731
            ev2 = lambda t, x, s: thr_at(t) - abs_base_acc(t, x)  # noqa: E731
        elif phase == "R":
            ev1 = lambda t, x, s: math.pi / 2 - s * x[0]  # noqa: E731
            ev2 = lambda t, x, s: s * x[1]  # noqa: E731
        else:
            ev1 = lambda t, x, s: s * x[0]  # noqa: E731
            ev2 = lambda t, x, s: -s * x[1]  # noqa: E731
        for ev in (ev1, ev2):
            ev.terminal, ev.direction = True, -1
        events = [ev1, ev2]
        if not fixed:
            peak = lambda t, x, s: x[3]  # noqa: E731
            peak.terminal, peak.direction = False, 0
            events.append(peak)
        fall_index = touch_index = None
        if vertical is not None:
            fall = lambda t, x, s: gravity(t)  # noqa: E731
            fall.terminal, fall.direction = True, -1
            fall_index = len(events)
            events.append(fall)
        if stop is not None:  # the stop's kink ends a solve, both ways

            def touch(t, x, s, since=last_touch):
                # Just after a touch, its side (the solve starts on the root).
                if t <= since[0] + 1e-9:
                    return since[1]
                return stop_margin(x)

            touch.terminal, touch.direction = True, 0
            touch_index = len(events)
            events.append(touch)
        sol = solve_ivp(
            rhs,
            (t, _next_break(breaks, t, t_end)),
            x,
            method="DOP853",
            rtol=rtol,
            atol=atol,
            events=events,
            args=(0 if phase == "T" else s,),
            max_step=max_step,
            dense_output=bool(friction_samples),
        )
        evaluations += sol.nfev
        if friction_samples:
            sp = 0 if phase == "T" else s
            fractions = np.arange(friction_samples) / friction_samples
            times = (sol.t[:-1, None] + np.diff(sol.t)[:, None] * fractions).ravel()
            times = np.append(times, sol.t[-1])
            for tt, xx in zip(times, sol.sol(times).T):
                needed = max(needed, force_ratio(tt, xx, sp))
        if not fixed and len(sol.y_events[2]):
            max_u = max(max_u, np.max(np.abs(sol.y_events[2][:, 2])))
        if fall_index is not None and len(sol.t_events[fall_index]):
            t, x = sol.t[-1], sol.y[:, -1].copy()
            max_th = max(max_th, abs(x[0]))
            if not fixed:  # |u| where the block would leave its base
                max_u = max(max_u, abs(x[2]))
            flight = True
            break
        hit = [len(sol.t_events[0]) > 0, len(sol.t_events[1]) > 0]
        if hit[0] and hit[1]:
            hit[int(sol.t_events[0][0] > sol.t_events[1][0])] = False
        t, x = sol.t[-1], sol.y[:, -1].copy()
        if not fixed:
            max_u = max(max_u, abs(x[2]))
        max_th = max(max_th, abs(x[0]))
        if not (hit[0] or hit[1]):
            if touch_index is not None and len(sol.t_events[touch_index]):
                # The push starts (the margin rises through 0), else it ends.
                outward = stop_margin_rate(t, x, 0 if phase == "T" else s) > 0
                last_touch[:] = [t, 1e-30 if outward else -1e-30]
                # Entering, the dashpot's force jumps: a block at rest may
                # uplift at once (its condition would start past its root).
                s0 = uplift_now(t, x, entering=True) if phase == "T" else 0
                if outward and s0:
                    phase, s, rocked = "R", s0, True
                    uplift_time = t if math.isnan(uplift_time) else uplift_time
            if t < t_end:
                continue  # a kink: the same phase goes on
            break
        if phase == "T":
            phase, s = "R", 1 if hit[0] else -1
            rocked = True
            uplift_time = t if math.isnan(uplift_time) else uplift_time
        elif phase == "R" and hit[0]:
            overturned = True
            max_th = math.pi / 2
            break
        elif phase == "R":
            phase = "F"
        elif hit[1]:
            phase = "R"
        else:
            impacts += 1
            thd = x[1]
            ud = 0.0 if fixed else x[3]
            rise = (e * thd) ** 2 / (2 * p2 * gravity(t) / G * math.sin(alpha))
            if e <= 0 or (rise < rest_tolerance * alpha and chatter_ends(t, x, thd)):
                x[0] = x[1] = 0.0
                if not fixed:
                    x[3] = ud + m * h * thd / M
                phase = "T"
                if friction_samples:
                    chatter = max(e, 0.0) * thd
                    needed = max(
                        needed,
                        impulse_ratio(
                            s, thd, chatter, ud, ud + m * h * (thd - chatter) / M
                        ),
                    )
                s0 = uplift_now(t, x)
                if s0:
                    phase, s = "R", s0
            else:
                x[0], x[1] = 0.0, e * thd
                if not fixed and restitution is None and restitution_factor == 1.0:
                    x[3] = ud + 6 * m * h * b * b * thd / den  # Eq. 2.14
                elif not fixed:  # M u'+ + m h theta'+ = M u'- + m h theta'-
                    x[3] = ud + m * h * (thd - x[1]) / M
                if friction_samples:
                    needed = max(
                        needed, impulse_ratio(s, thd, x[1], ud, 0.0 if fixed else x[3])
                    )
                phase, s = "R", -s
            log.append((thd, x[1], ud, 0.0 if fixed else x[3]))
    else:
        raise RuntimeError("reference: too many segments")
    outcome = 2 if overturned else (1 if rocked else 0)
    out = {} if not friction_samples else dict(friction_needed=needed)
    return out | dict(
        flight=flight,
        outcome=outcome,
        max_rotation=max_th / alpha,
        max_base_displacement=max_u,
        impacts=impacts,
        uplift_time=uplift_time,
        impact_log=log,
        evaluations=evaluations,
    )
