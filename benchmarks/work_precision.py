"""Work-precision: error against a tight SciPy reference vs wall time, per solver.

Cases (San Fernando PCD/SN pulse): a fixed base with many impacts, a linear
isolator that rocks, one that overturns, a friction pendulum that rocks.
Solvers: Tsit5, Dopri5, Dopri8, Kvaerno5 (implicit) over rtol 1e-3 .. 1e-11
(atol = rtol / 100), and classic RK4 at fixed steps with events located at step
ends only (the naive baseline). Also a 240-cell map: share of cells classified
like the SciPy reference against map time. Writes PNGs, JSON and Markdown to
benchmarks/results/.

    python benchmarks/work_precision.py [--quick]
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import diffrax
import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import jaxrock as jr
from jaxrock import _simulate
from jaxrock._solvers import RK4

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import reference as ref

A, FREQ, GAMMA, PHASE = 1.15, 0.68, 1.6, 180.0
PULSE = jr.MPPulse(A, FREQ, GAMMA, PHASE)
LINEAR = (jr.LinearIsolator(2.0, 0.35, 0.5), ("linear", 2.0, 0.35, 0.5))
CASES = {
    "fixed, many impacts": (3.0, 2.0, (jr.FixedBase(), ("fixed",))),
    "linear, rocking": (3.0, 0.5, LINEAR),
    "linear, overturning": (6.5, 3.5, LINEAR),
    "friction pendulum, rocking": (
        4.0,
        1.0,
        (
            jr.FrictionPendulum(0.11, 2.24, 0.5),
            ("fps", 0.11, 2.24, 0.5, 5e-4, 1.0, 0.9, 0.1, 2.0),
        ),
    ),
}
SOLVERS = {
    "Tsit5": diffrax.Tsit5(),
    "Dopri5": diffrax.Dopri5(),
    "Dopri8": diffrax.Dopri8(),
    "Kvaerno5": diffrax.Kvaerno5(),
}
STAGES = {"Tsit5": 6, "Dopri5": 6, "Dopri8": 12, "Kvaerno5": 7, "RK4": 4}


def timed(block, base, opts, repeats=2):
    duration = jr._misc.as_float(float(PULSE.end_time) + 5.0)
    out = _simulate._run_jit(block, base, PULSE, duration, opts)
    jax.block_until_ready(out)
    best = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        out = jax.block_until_ready(
            _simulate._run_jit(block, base, PULSE, duration, opts)
        )
        best = min(best, time.perf_counter() - t)
    return out, best


def rel(a, b):
    return abs(a - b) / max(abs(b), 1e-300)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    p.add_argument(
        "--plot-only",
        action="store_true",
        help="redraw from results/work_precision.json",
    )
    p.add_argument(
        "--maps-only",
        action="store_true",
        help="re-measure the maps only; keep the cases of results/work_precision.json",
    )
    a = p.parse_args()
    out = ROOT / "benchmarks" / "results"
    if a.plot_only:
        data = json.loads((out / "work_precision.json").read_text())
        return plots(data["cases"], data["maps"], out)
    rtols = (
        [1e-3, 1e-5, 1e-7, 1e-9, 1e-11] if a.quick else [10.0**-k for k in range(3, 12)]
    )
    steps = [0.02, 0.005, 0.001] if a.quick else [0.05, 0.02, 0.01, 0.005, 0.002, 0.001]
    acc, t_end, max_step = ref.mp_pulse(A, FREQ, GAMMA, PHASE)
    rows = []
    if a.maps_only:
        rows = json.loads((out / "work_precision.json").read_text())["cases"]
    for case, (lam, size, (base, ref_base)) in {} if a.maps_only else CASES.items():
        truth = ref.simulate(
            lam, size, ref_base, acc, t_end + 5.0, max_step, rtol=1e-12, atol=1e-14
        )
        block = jr.Block(lam, size)
        runs = [
            (name, dict(rtol=r, atol=r * 1e-2, solver=s), r)
            for name, s in SOLVERS.items()
            for r in rtols
        ]
        runs += [("RK4", dict(step=h, solver=RK4()), h) for h in steps]
        for name, kw, knob in runs:
            res, seconds = timed(block, base, jr.SolverOptions(**kw))
            row = dict(
                case=case,
                solver=name,
                knob=knob,
                seconds=seconds,
                status=jr.Status(int(res.status)).name,
                steps=int(res.steps),
                evaluations=int(res.steps) * STAGES[name],
                outcome_ok=int(res.outcome) == truth["outcome"],
                impacts_ok=int(res.impacts) == truth["impacts"],
                rotation_error=rel(float(res.max_rotation), truth["max_rotation"]),
                uplift_error=abs(float(res.uplift_time) - truth["uplift_time"]),
                displacement_error=(
                    rel(
                        float(res.max_base_displacement), truth["max_base_displacement"]
                    )
                    if truth["max_base_displacement"]
                    else 0.0
                ),
            )
            rows.append(row)
            print(json.dumps(row), flush=True)

    # A 240-cell map: share of cells classified like the reference, against time.
    lam = np.linspace(1.5, 7.0, 20)
    size = np.linspace(0.2, 4.0, 12)
    map_rows = []
    for key, (base, ref_base) in {
        "fixed": (jr.FixedBase(), ("fixed",)),
        "linear": LINEAR,
    }.items():
        truth = np.array(
            [
                [
                    ref.simulate(l_, s_, ref_base, acc, t_end + 5.0, max_step)[
                        "outcome"
                    ]
                    for s_ in size
                ]
                for l_ in lam
            ]
        )
        knobs = [("Tsit5", dict(rtol=r, atol=r * 1e-2), r) for r in rtols]
        for name, kw, knob in knobs:
            jr.behavior_map(lam, size, base, PULSE, progress=False, **kw)
            bm = jr.behavior_map(lam, size, base, PULSE, progress=False, **kw)
            map_rows.append(
                dict(
                    base=key,
                    solver=name,
                    knob=knob,
                    seconds=bm.seconds,
                    agreement=float(np.mean(bm.outcome == truth)),
                )
            )
            print(json.dumps(map_rows[-1]), flush=True)

    out.mkdir(parents=True, exist_ok=True)
    (out / "work_precision.json").write_text(
        json.dumps(dict(cases=rows, maps=map_rows), indent=2)
    )
    plots(rows, map_rows, out)


def plots(rows, map_rows, out):
    fig, axes = plt.subplots(2, len(CASES), figsize=(4.2 * len(CASES), 7.5))
    for j, case in enumerate(CASES):
        for name in list(SOLVERS) + ["RK4"]:
            rs = [
                r
                for r in rows
                if r["case"] == case
                and r["solver"] == name
                and r["status"] == "SUCCESS"
            ]
            # An overturning case has max rotation pi / (2 alpha) exactly: show
            # the uplift time's error there instead.
            key = "uplift_error" if "overturning" in case else "rotation_error"
            err = [max(r[key], 1e-16) for r in rs]
            axes[0, j].loglog([r["seconds"] for r in rs], err, "o-", label=name, ms=3)
            axes[1, j].loglog(
                [r["evaluations"] for r in rs], err, "o-", label=name, ms=3
            )
        axes[0, j].set_title(case, fontsize=9)
        axes[0, j].set_xlabel("wall time per analysis (s)")
        axes[1, j].set_xlabel("vector-field evaluations (steps x stages)")
        for ax in axes[:, j]:
            ax.set_ylabel(
                "error of uplift time (s)"
                if "overturning" in case
                else "rel. error of max|theta|/alpha"
            )
            ax.axhline(1e-6, color="gray", lw=0.5, ls="--")
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "work_precision.png", dpi=90)
    fig, ax = plt.subplots(figsize=(5, 4))
    for key in ("fixed", "linear"):
        rs = [r for r in map_rows if r["base"] == key]
        ax.semilogx(
            [r["seconds"] for r in rs],
            [r["agreement"] for r in rs],
            "o",
            label=f"{key} (Tsit5; labels: log10 rtol)",
        )
        for r in rs:
            ax.annotate(
                f"{np.log10(r['knob']):.0f}",
                (r["seconds"], r["agreement"]),
                fontsize=7,
                xytext=(2, 4 if key == "fixed" else -9),
                textcoords="offset points",
            )
    ax.set_xlabel("map time (s, 240 cells)")
    ax.set_ylabel("cells classified like the reference")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "work_precision_map.png", dpi=90)
    lines = [
        "| case | solver | rtol or step | time (s) | steps | max-rotation error "
        "| uplift error (s) | impacts ok |",
        "|" + "---|" * 8,
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['solver']} | {r['knob']:g} | "
            f"{r['seconds']:.4f} | {r['steps']} | {r['rotation_error']:.1e} | "
            f"{r['uplift_error']:.1e} | {r['impacts_ok']} |"
        )
    (out / "work_precision.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
