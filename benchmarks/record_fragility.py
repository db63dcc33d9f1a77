"""Fragility of one block over the FEMA P695 near-field pulse suite: the 28
horizontal components (14 records), each scaled over a range of intensities
(an incremental analysis), on a fixed base and on the paper's linear
isolator. Writes the figure docs/fragility_fema_p695_nearfield_pulse.png and
benchmarks/results/record_fragility.{json,md} (the fits and the time).

    python benchmarks/record_fragility.py [--slenderness 4] [--size 1]
        [--scales 0.1:3:16]
"""

import argparse
import os
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Times include compiling: no compiled loop from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr  # noqa: E402
from jaxrock import plot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--slenderness", type=float, default=4.0)
    p.add_argument("--size", type=float, default=1.0)
    p.add_argument("--scales", default="0.1:3:16")
    a = p.parse_args()
    start, stop, n = a.scales.split(":")
    scales = np.geomspace(float(start), float(stop), int(n))
    suite = jr.Record.stack(jr.records.fema_p695("nearfield_pulse"))
    bases = {
        "fixed base": jr.FixedBase(),
        "linear isolator": jr.LinearIsolator(2.0, 0.35, 0.5),
    }
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    rows = []
    for ax, (name, base) in zip(axes, bases.items()):
        t = time.perf_counter()
        frag = jr.fragility(
            a.slenderness, a.size, base, suite, scales=scales, progress=False
        )
        seconds = time.perf_counter() - t
        plot.fragility(
            frag, ax=ax, title=f"{name}: lambda = {a.slenderness:g}, r = {a.size:g} m"
        )
        rows.append(
            dict(
                base=name,
                analyses=int(frag.im.size),
                seconds=seconds,
                median_rocking_pga=frag.median_rocking,
                beta_rocking=frag.beta_rocking,
                median_overturning_pga=frag.median_overturning,
                beta_overturning=frag.beta_overturning,
                not_converged=int(np.sum(frag.status != jr.Status.SUCCESS)),
            )
        )
        print(rows[-1], flush=True)
    fig.suptitle(
        "FEMA P695 near-field pulse suite (28 components), scaled", fontsize=10
    )
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "fragility_fema_p695_nearfield_pulse.png", dpi=110)
    md = markdown_table(
        rows,
        [
            ("base", "{base}"),
            ("analyses", "{analyses}"),
            ("time incl. compile (s)", "{seconds:.1f}"),
            ("median PGA to rock (m/s^2)", "{median_rocking_pga:.3g}"),
            ("beta", "{beta_rocking:.2f}"),
            ("median PGA to overturn (m/s^2)", "{median_overturning_pga:.3g}"),
            ("beta", "{beta_overturning:.2f}"),
            ("not converged", "{not_converged}"),
        ],
    )
    write_results("record_fragility", rows, md)


if __name__ == "__main__":
    main()
