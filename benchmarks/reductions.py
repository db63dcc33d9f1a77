"""What "model no more than a scene needs" buys, on the paper's 2,440-cell map.

Each reduction jaxrock makes is timed against the same scene without it
(San Fernando PCD/SN, rtol 1e-8, best of --repeats, after compilation):

- fixed base: the free rocking after the pulse finished in closed form
  (`_free.py`), against integrated (the engines take a base without a state
  as a fixed base, so a fixed base carrying an idle state is not a scene
  they run);
- linear isolator: no hysteretic state, against z carried with zero rate, and
  against z integrated by Bouc-Wen (paper's parameters) while its force is
  zero: a one-model-for-all isolator F = k u + c u' + Q z with Q = 0;
- friction pendulum: z in closed form (eta = 2), against z integrated;
- a map keeps no time history: a map's cell against `simulate(history=True)`
  (2,001 samples of 7 channels, 112 kB a cell) on a sample of cells.

Every variant must classify each cell as the reduced model does (checked).
Writes benchmarks/results/reductions.{json,md}.

    python benchmarks/reductions.py [--repeats 3] [--history-sample 8]
"""

import argparse
import json
import time
from pathlib import Path
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

import jaxrock as jr

RESULTS = Path(__file__).resolve().parent / "results"


class IntegratedTailFixedBase(jr.FixedBase):
    """A fixed base whose free rocking after the pulse is integrated step by step
    (as `simulate` does) instead of finished in closed form."""

    free_rocking_closed_form: ClassVar[bool] = False


class CarriedLinear(jr.LinearIsolator):
    """A linear isolator that carries an idle Bouc-Wen variable z (zero rate)."""

    n_states: ClassVar[int] = 3

    def initial_state(self):
        return jnp.zeros(3, dtype=self.period.dtype)

    def rates(self, state, u_ddot):
        return jnp.stack([state[1], u_ddot, jnp.zeros_like(u_ddot)])


class BoucWenLinear(CarriedLinear):
    """A linear isolator with z integrated by Bouc-Wen (Y = 0.5 mm, A = 1,
    gamma = 0.9, beta = 0.1, eta = 2) but no hysteretic force (Q = 0)."""

    def rates(self, state, u_ddot):
        u_dot, z = state[1], state[2]
        z_dot = u_dot - 0.9 * jnp.abs(u_dot) * z * jnp.abs(z) - 0.1 * u_dot * z**2
        return jnp.stack([u_dot, u_ddot, z_dot / 5e-4])


def time_map(base, lam, size, motion, repeats):
    jr.behavior_map(lam, size, base, motion, progress=False)  # compile
    runs = [
        jr.behavior_map(lam, size, base, motion, progress=False) for _ in range(repeats)
    ]
    best = min(runs, key=lambda r: r.seconds)
    return best


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--history-sample", type=int, default=8)
    p.add_argument("--table-only", action="store_true", help="rewrite the table")
    a = p.parse_args()
    if a.table_only:
        return write_table(json.loads((RESULTS / "reductions.json").read_text()))
    lam = np.round(np.arange(1.0, 7.0 + 1e-9, 0.1), 10)
    size = np.round(np.arange(0.1, 4.0 + 1e-9, 0.1), 10)
    motion = jr.near_fault_pulse("San Fernando PCD/SN")
    pairs = [
        (
            "fixed base",
            "free rocking after the pulse in closed form",
            jr.FixedBase(),
            "integrated",
            IntegratedTailFixedBase(),
        ),
        (
            "linear isolator",
            "no z",
            jr.LinearIsolator(2.0, 0.35, 0.5),
            "z carried (zero rate)",
            CarriedLinear(2.0, 0.35, 0.5),
        ),
        (
            "linear isolator",
            "no z",
            jr.LinearIsolator(2.0, 0.35, 0.5),
            "z by Bouc-Wen, Q = 0",
            BoucWenLinear(2.0, 0.35, 0.5),
        ),
        (
            "friction pendulum",
            "z in closed form (eta = 2)",
            jr.FrictionPendulum(0.11, 2.24, 0.5),
            "z integrated",
            jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5),
        ),
    ]
    rows, reduced_maps = [], {}
    for scene, reduced_name, reduced, full_name, full in pairs:
        if scene not in reduced_maps:
            reduced_maps[scene] = time_map(reduced, lam, size, motion, a.repeats)
        r = reduced_maps[scene]
        f = time_map(full, lam, size, motion, a.repeats)
        same = int(np.sum(r.outcome == f.outcome))
        rot = float(np.max(np.abs(r.max_rotation - f.max_rotation)))
        rows.append(
            dict(
                scene=scene,
                reduced=reduced_name,
                full=full_name,
                reduced_s=r.seconds,
                full_s=f.seconds,
                speedup=f.seconds / r.seconds,
                reduced_steps=int(r.steps.sum()),
                full_steps=int(f.steps.sum()),
                same_outcome=same,
                cells=int(r.outcome.size),
                max_rotation_diff=rot,
            )
        )
        print(rows[-1], flush=True)

    # No time history: a map's cell against simulate(history=True).
    rng = np.random.default_rng(0)
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    cells = rng.choice(lam.size * size.size, a.history_sample, replace=False)
    i, j = np.divmod(cells, size.size)
    jr.simulate(jr.Block(lam[i[0]], size[j[0]]), base, motion, history=True)  # compile
    t = time.perf_counter()
    for ii, jj in zip(i, j):
        h = jr.simulate(jr.Block(lam[ii], size[jj]), base, motion, history=True)
    per_cell_history = (time.perf_counter() - t) / len(cells)
    fields = h.history
    history_bytes = sum(
        np.asarray(getattr(fields, k)).nbytes
        for k in ("t", "theta", "theta_dot", "u", "u_dot", "z", "regime")
    )
    per_cell_map = reduced_maps["linear isolator"].seconds / lam.size / size.size
    history = dict(
        per_cell_map_ms=1e3 * per_cell_map,
        per_cell_history_ms=1e3 * per_cell_history,
        ratio=per_cell_history / per_cell_map,
        history_bytes_per_cell=history_bytes,
        map_bytes_per_cell=8 * 8,
    )
    print(history)

    RESULTS.mkdir(exist_ok=True)
    data = dict(rows=rows, history=history)
    (RESULTS / "reductions.json").write_text(json.dumps(data, indent=1))
    write_table(data)


def write_table(data):
    lines = [
        "| scene | reduced | run (s) | steps | us/step | without the reduction "
        "| run (s) | steps | us/step | cost of not reducing | same outcome |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        lines.append(
            f"| {r['scene']} | {r['reduced']} | {r['reduced_s']:.2f} | "
            f"{r['reduced_steps']:,} | {1e6 * r['reduced_s'] / r['reduced_steps']:.2f} "
            f"| {r['full']} | {r['full_s']:.2f} | {r['full_steps']:,} | "
            f"{1e6 * r['full_s'] / r['full_steps']:.2f} | {r['speedup']:.2f}x | "
            f"{r['same_outcome']}/{r['cells']} |"
        )
    h = data["history"]
    lines.append(
        f"| linear isolator | no time history (map) | "
        f"{h['per_cell_map_ms']:.2f} ms/cell | | | `simulate(history=True)` | "
        f"{h['per_cell_history_ms']:.0f} ms/cell | | | {h['ratio']:.0f}x, "
        f"{h['history_bytes_per_cell'] / 1e3:.0f} kB vs 64 B a cell | |"
    )
    (RESULTS / "reductions.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
