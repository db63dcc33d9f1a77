"""Behavior maps on every isolator: the paper's 61 x 40 grid under the San
Fernando PCD/SN pulse and under the Pacoima Dam 164 record, on the friction
pendulum, the bilinear isolator and the two rolling isolators.

For each: compile time (the first call less the best run), run time (best of
--repeats), analyses per second, steps per analysis, lane efficiency and the
outcomes' counts. The isolators: the paper's friction pendulum (mu 0.11,
R 2.24 m), a lead-rubber bearing (Q / Mg 0.06, T 2.5 s, Y 15 mm), balls in
spherical dishes (R 1.5 m, mu_r 0.005) and in cones (slope 0.1, mu_r 0.005),
each with a mass ratio of 0.5. Prints a Markdown table and writes
benchmarks/results/isolators.{json,md}; --plot PATH draws the pulse maps
side by side (docs/map_isolators_san_fernando.png).

    python benchmarks/isolators.py [--repeats 2] [--bases fps,bilinear,...]
        [--plot docs/map_isolators_san_fernando.png]
"""

import argparse
import os
import time

# Compile times are measured cold: no compiled loop from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

import numpy as np  # noqa: E402
from _results import markdown_table, write_results  # noqa: E402
from record_maps import SIZE, SLENDERNESS, pacoima  # noqa: E402

import jaxrock as jr  # noqa: E402

BASES = {
    "fps": jr.FrictionPendulum(0.11, 2.24, 0.5),
    "bilinear": jr.BilinearIsolator(0.06, 2.5, 0.015, 0.5),
    "rolling-sphere": jr.SphericalRollingIsolator(1.5, 0.005, 0.5),
    "rolling-cone": jr.ConicalRollingIsolator(0.1, 0.005, 0.5),
}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--bases", default=",".join(BASES))
    p.add_argument("--plot", default=None, help="a picture of the pulse maps")
    a = p.parse_args()
    motions = {
        "San Fernando PCD/SN": jr.near_fault_pulse("San Fernando PCD/SN"),
        "Pacoima Dam 164": pacoima(),
    }
    rows, maps = [], {}
    for motion_name, motion in motions.items():
        for name in a.bases.split(","):
            base = BASES[name]

            def call():
                return jr.behavior_map(SLENDERNESS, SIZE, base, motion, progress=False)

            t = time.perf_counter()
            best = call()
            first = time.perf_counter() - t
            for _ in range(a.repeats):
                again = call()
                best = again if again.seconds < best.seconds else best
            counts = best.counts()
            maps[name, motion_name] = best
            rows.append(
                dict(
                    base=name,
                    isolator=base.describe(),
                    motion=motion_name,
                    cells=int(best.outcome.size),
                    compile_s=max(first - best.seconds, 0.0),
                    run_s=best.seconds,
                    analyses_per_s=best.outcome.size / best.seconds,
                    steps_per_analysis=float(np.mean(best.steps)),
                    lane_efficiency=best.lane_efficiency,
                    max_base_displacement=float(np.max(best.max_base_displacement)),
                    **counts,
                )
            )
            print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("base", "{base}"),
            ("motion", "{motion}"),
            ("compile (s)", "{compile_s:.1f}"),
            ("run (s)", "{run_s:.2f}"),
            ("analyses/s", "{analyses_per_s:,.0f}"),
            ("steps/analysis", "{steps_per_analysis:.0f}"),
            ("lane eff.", "{lane_efficiency:.0%}"),
            (
                "no rocking / rocking / overturned",
                "{no_rocking} / {rocking} / {overturned}",
            ),
            ("max abs(u) (m)", "{max_base_displacement:.2f}"),
            ("not converged", "{not_converged}"),
        ],
    )
    write_results("isolators", rows, md)
    if a.plot:
        draw(maps, a.plot)


def draw(maps, path):
    """The San Fernando maps side by side, two to a row, to `path`."""
    from jaxrock import plot

    pulse = [(k, m) for k, m in maps.items() if k[1] == "San Fernando PCD/SN"]
    titles = [BASES[k[0]].describe() for k, _ in pulse]
    fig = plot.compare_maps([m for _, m in pulse], titles, columns=2)
    fig.savefig(path, dpi=80)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
