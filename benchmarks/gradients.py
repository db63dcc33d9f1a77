"""Cost of a value-and-gradient against a value alone (forward mode, two parameters).

d(max|theta|/alpha)/d(T_s, xi) of a linear isolator, for one block and for a
batch of 256 blocks (vmapped), San Fernando PCD/SN pulse, rtol 1e-8. Best of
--repeats after compilation. Writes benchmarks/results/gradients.{json,md}.
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np
from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr
from jaxrock._results import SolverOptions
from jaxrock._simulate import run

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
DURATION = jnp.asarray(float(PULSE.end_time) + 5.0)


def value(params, lam, r):
    base = jr.LinearIsolator(params[0], params[1], 0.5)
    return run(jr.Block(lam, r), base, PULSE, DURATION, SolverOptions()).max_rotation


def value_and_grad(params, lam, r):
    grad, v = jax.jacfwd(lambda p: (value(p, lam, r),) * 2, has_aux=True)(params)
    return v, grad


def best_time(f, *args, repeats):
    jax.block_until_ready(f(*args))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f(*args))
        times.append(time.perf_counter() - t)
    return min(times)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args()
    params = jnp.array([2.0, 0.35])
    rng = np.random.default_rng(0)
    rows = []
    for n in (1, 256):
        lam = jnp.asarray(rng.uniform(2.5, 6.0, n))
        r = jnp.asarray(rng.uniform(0.3, 3.0, n))
        f_val = jax.jit(jax.vmap(value, in_axes=(None, 0, 0)))
        f_grad = jax.jit(jax.vmap(value_and_grad, in_axes=(None, 0, 0)))
        tv = best_time(f_val, params, lam, r, repeats=a.repeats)
        tg = best_time(f_grad, params, lam, r, repeats=a.repeats)
        rows.append(
            dict(blocks=n, value_s=tv, value_and_grad_s=tg, ratio=tg / tv, parameters=2)
        )
        print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("blocks", "{blocks}"),
            ("value (s)", "{value_s:.4f}"),
            ("value + gradient (s)", "{value_and_grad_s:.4f}"),
            ("ratio", "{ratio:.1f}"),
        ],
    )
    write_results("gradients", rows, md)


if __name__ == "__main__":
    main()
