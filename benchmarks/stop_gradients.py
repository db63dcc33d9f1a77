"""Accuracy of values and derivatives through a damped stop, against rtol.

Random linear isolators (period 1.5-3 s, damping 0.02-0.2, mass ratio 0.5)
with a `Stop` (capacity 0.03-0.1 m, period 0.1-0.5 s, damping 0.1-0.7)
carry blocks of size 1 m under an MP pulse
(Tp = 1 s, gamma = 2.5, nu = 90 deg, amplitude 1-2.5 m/s^2), 5 s. For each,
max|u| and d max|u| / d(amplitude) (`jax.jacfwd`) at rtol 1e-6, 1e-8 and
1e-10 (atol rtol / 100), for squat blocks (slenderness 0.2-0.5, which
the stop's shocks uplift now and then) and slender ones (2-5, which rock
and impact), against max|u| at rtol 1e-13 and its central
difference (h = 1e-4 of the amplitude). Cases whose outcome or impacts
change within +-h are skipped (a derivative does not hold across them).
Writes benchmarks/results/stop_gradients.{json,md}: the geometric mean and
the largest relative error of each, and the mean steps.
"""

import argparse

import jax
import jax.numpy as jnp
import numpy as np
from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr

RTOLS = (1e-6, 1e-8, 1e-10)
TIGHT = dict(rtol=1e-13, atol=1e-15)


def response(amplitude, case, **tolerance):
    """(max|u|, outcome, impacts, steps) of one case."""
    period, damping, capacity, stop_period, stop_damping, slenderness = case
    stop = jr.Stop(stop_period, stop_damping)
    base = jr.LinearIsolator(period, damping, 0.5, capacity=capacity, stop=stop)
    pulse = jr.MPPulse(amplitude, 1.0, 2.5, 90.0)
    r = jr.simulate(jr.Block(slenderness, 1.0), base, pulse, duration=5.0, **tolerance)
    return jnp.stack([r.max_base_displacement, r.outcome, r.impacts, r.steps])


def errors(amplitude, case):
    """{rtol: (value error, derivative error, steps)}, or None where the
    outcome or impacts change within +-h."""
    h = 1e-4 * amplitude
    exact, above, below = (
        response(a, case, **TIGHT) for a in (amplitude, amplitude + h, amplitude - h)
    )
    if not (np.all(above[1:3] == exact[1:3]) and np.all(below[1:3] == exact[1:3])):
        return None
    central = float((above[0] - below[0]) / (2 * h))
    out = {}
    for rtol in RTOLS:
        tolerance = dict(rtol=rtol, atol=rtol * 1e-2)
        value = response(amplitude, case, **tolerance)
        slope = jax.jacfwd(lambda a: response(a, case, **tolerance)[0])(amplitude)
        out[rtol] = (
            abs(float(value[0]) / float(exact[0]) - 1.0),
            abs(float(slope) / central - 1.0),
            float(value[3]),
        )
    return out


def summary(kept, rtol):
    """The geometric mean and the largest of the errors at `rtol`, and the
    mean steps, over the cases kept."""
    value, slope, steps = np.array([k[rtol] for k in kept]).T
    return dict(
        rtol=rtol,
        cases=len(kept),
        value_gmean=float(np.exp(np.mean(np.log(value + 1e-17)))),
        value_max=float(value.max()),
        derivative_gmean=float(np.exp(np.mean(np.log(slope + 1e-17)))),
        derivative_max=float(slope.max()),
        steps=float(steps.mean()),
    )


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--cases", type=int, default=24)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    rng = np.random.default_rng(a.seed)
    rows = []
    for blocks, slenderness in (("squat", (0.2, 0.5)), ("slender", (2.0, 5.0))):
        kept = []
        for _ in range(a.cases):
            case = (
                rng.uniform(1.5, 3.0),
                rng.uniform(0.02, 0.2),
                rng.uniform(0.03, 0.1),
                rng.uniform(0.1, 0.5),
                rng.uniform(0.1, 0.7),
                rng.uniform(*slenderness),
            )
            found = errors(rng.uniform(1.0, 2.5), case)
            if found is not None:
                kept.append(found)
        rows += [dict(blocks=blocks, **summary(kept, rtol)) for rtol in RTOLS]
    md = markdown_table(
        rows,
        [
            ("blocks", "{blocks}"),
            ("rtol", "{rtol:.0e}"),
            ("cases", "{cases}"),
            ("max abs(u), geometric mean", "{value_gmean:.1e}"),
            ("max abs(u), largest", "{value_max:.1e}"),
            ("derivative, geometric mean", "{derivative_gmean:.1e}"),
            ("derivative, largest", "{derivative_max:.1e}"),
            ("steps", "{steps:.0f}"),
        ],
    )
    write_results("stop_gradients", rows, md)


if __name__ == "__main__":
    main()
