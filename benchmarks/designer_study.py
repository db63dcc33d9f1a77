"""A designer's study: which isolator keeps one statue standing? A statue
(slenderness 4, half-diagonal 1 m) under the 56 components of the FEMA P695
near-field suite as recorded, on a fixed base and on lead-rubber bearings
(`BilinearIsolator`, mass ratio 0.5, yield 15 mm) over a grid of periods and
strengths, each with a displacement capacity of 0.25 m. One map holds every
isolator and record (the isolators as a batch of bases).

Writes docs/designer_study.png (the probability of overturning and of
passing the capacity, per period and strength) and
benchmarks/results/designer_study.{md,json}.

    python benchmarks/designer_study.py [--periods 1.5:3.5:5]
        [--strengths 0.03:0.12:4] [--capacity 0.25]
"""

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _axis(text):
    start, stop, n = text.split(":")
    return np.linspace(float(start), float(stop), int(n))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--periods", default="1.5:3.5:5")
    p.add_argument("--strengths", default="0.03:0.12:4")
    p.add_argument("--capacity", type=float, default=0.25)
    a = p.parse_args()
    periods, strengths = _axis(a.periods), _axis(a.strengths)
    suite = jr.Record.stack(jr.records.fema_p695("nearfield"))
    statue = dict(slenderness=[4.0], size=[1.0])
    fixed = jr.behavior_map(**statue, base=jr.FixedBase(), motion=suite)
    q, t = np.meshgrid(strengths, periods, indexing="ij")
    bases = jr.BilinearIsolator(
        strength=q,
        period=t,
        yield_displacement=0.015,
        mass_ratio=0.5,
        capacity=a.capacity,
    )
    start = time.perf_counter()
    bm = jr.behavior_map(**statue, base=bases, motion=suite)
    seconds = time.perf_counter() - start
    # (strength, period, record, 1, 1) -> per isolator over the records
    status, outcome = bm.status[..., 0, 0], bm.outcome[..., 0, 0]
    u = bm.max_base_displacement[..., 0, 0]
    overturned = np.mean(outcome == jr.Outcome.OVERTURNED, axis=-1)
    passed = np.mean(u >= a.capacity, axis=-1)
    undecided = int(np.sum(status == jr.Status.UNDECIDED))
    p_fixed = float(np.mean(fixed.outcome == jr.Outcome.OVERTURNED))
    rows = [
        dict(
            strength=float(q[i, j]),
            period=float(t[i, j]),
            overturning=float(overturned[i, j]),
            capacity_passed=float(passed[i, j]),
            median_u=float(np.median(u[i, j])),
        )
        for i, j in np.ndindex(q.shape)
    ]
    print(f"{bm.outcome.size} analyses in {seconds:.1f} s; fixed base: P = {p_fixed}")
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, values, title in (
        (axes[0], overturned, "P(overturning)"),
        (axes[1], passed, f"P(max |u| > {a.capacity:g} m)"),
    ):
        image = ax.imshow(
            values,
            origin="lower",
            aspect="auto",
            vmin=0,
            vmax=1,
            cmap="viridis",
            extent=(
                periods[0] - 0.25,
                periods[-1] + 0.25,
                strengths[0] - 0.015,
                strengths[-1] + 0.015,
            ),
        )
        for i, j in np.ndindex(q.shape):
            ax.text(
                t[i, j],
                q[i, j],
                f"{values[i, j]:.2f}",
                ha="center",
                va="center",
                color="w" if values[i, j] < 0.6 else "k",
                fontsize=8,
            )
        ax.set_xlabel("isolation period T (s)")
        ax.set_title(title, fontsize=10)
    axes[0].set_ylabel("strength Q / Mg")
    fig.colorbar(image, ax=axes, shrink=0.8)
    fig.suptitle(
        "statue lambda 4, r 1 m; FEMA P695 near-field suite (56 components) as "
        "recorded; "
        f"fixed base: P(overturning) = {p_fixed:.2f}",
        fontsize=9,
    )
    fig.savefig(ROOT / "docs" / "designer_study.png", dpi=110)
    md = markdown_table(
        rows,
        [
            ("Q / Mg", "{strength:.3f}"),
            ("T (s)", "{period:.2f}"),
            ("P(overturning)", "{overturning:.2f}"),
            ("P(max abs(u) > capacity)", "{capacity_passed:.2f}"),
            ("median max abs(u) (m)", "{median_u:.3f}"),
        ],
    )
    md += [
        "",
        f"Fixed base: P(overturning) = {p_fixed:.2f}. {bm.outcome.size} "
        f"analyses in {seconds:.1f} s, {undecided} undecided.",
    ]
    write_results("designer_study", rows, md)


if __name__ == "__main__":
    main()
