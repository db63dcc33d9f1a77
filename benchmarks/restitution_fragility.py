"""Fragility of one block with the coefficient of restitution it rebounds
with: the FEMA P695 near-field pulse suite (28 components) at 16 scales on a
fixed base, the momentum model's e0 times f = 0.8, 1.0 and 1.1. Writes
docs/fragility_restitution.png and benchmarks/results/restitution_fragility
.{json,md} (the fits).

    python benchmarks/restitution_fragility.py [--slenderness 3] [--size 1]
        [--factors 0.8,1.0,1.1] [--scales 0.1:3:16]
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--slenderness", type=float, default=3.0)
    p.add_argument("--size", type=float, default=1.0)
    p.add_argument("--factors", default="0.8,1.0,1.1")
    p.add_argument("--scales", default="0.1:3:16")
    a = p.parse_args()
    start, stop, n = a.scales.split(":")
    scales = np.geomspace(float(start), float(stop), int(n))
    suite = jr.Record.stack(jr.records.fema_p695("nearfield_pulse"))
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    rows = []
    for f in map(float, a.factors.split(",")):
        frag = jr.fragility(
            a.slenderness,
            a.size,
            jr.FixedBase(),
            suite,
            scales=scales,
            progress=False,
            restitution_factor=f,
        )
        im = np.geomspace(frag.im.min(), frag.im.max(), 200)
        (line,) = ax.plot(im, frag.probability(im), label=f"f = {f:g}")
        k = frag.overturned
        ax.plot(frag.im, k + 0.02 * (f - 1.0), "|", color=line.get_color(), alpha=0.4)
        rows.append(
            dict(
                factor=f,
                analyses=int(frag.im.size),
                overturned=int(k.sum()),
                median=float(frag.median_overturning),
                beta=float(frag.beta_overturning),
            )
        )
    block = jr.Block(a.slenderness, a.size)
    ax.set(
        xscale="log",
        xlabel="PGA (m/s^2)",
        ylabel="P(overturning)",
        title=f"FEMA P695 near-field pulse suite, fixed base, lambda = "
        f"{a.slenderness:g}, r = {a.size:g} m (e0 = "
        f"{float(1 - 1.5 * np.sin(block.alpha) ** 2):.3f})",
    )
    ax.title.set_fontsize(9)
    ax.legend(title="e = f e0")
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "fragility_restitution.png", dpi=110)
    md = markdown_table(
        rows,
        [
            ("f", "{factor:g}"),
            ("analyses", "{analyses}"),
            ("overturned", "{overturned}"),
            ("median PGA (m/s^2)", "{median:.3f}"),
            ("beta", "{beta:.3f}"),
        ],
    )
    write_results("restitution_fragility", rows, md)


if __name__ == "__main__":
    main()
