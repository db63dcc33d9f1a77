"""What a stop costs and changes: the paper's 2,440-cell maps under the San
Fernando PCD/SN pulse and the Pacoima Dam 164 record on the linear isolator
and the friction pendulum, free and with a stop at a capacity of 0.15 m (a
rubber bumper: `Stop(period=0.05, damping=0.2)`).

For each map: the best of `--repeats` runs of each (compiled first, calls
alternated), steps per analysis, the cells per outcome, and the cells whose
outcome the stop changes. Writes benchmarks/results/stops.{md,json}.

    python benchmarks/stops.py [--repeats 2] [--capacity 0.15]
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import markdown_table, write_results  # noqa: E402
from record_maps import SIZE, SLENDERNESS, pacoima  # noqa: E402

import jaxrock as jr  # noqa: E402


def isolators(capacity):
    stop = dict(capacity=capacity, stop=jr.Stop(period=0.05, damping=0.2))
    return {
        "linear": (
            jr.LinearIsolator(2.0, 0.35, 0.5),
            jr.LinearIsolator(2.0, 0.35, 0.5, **stop),
        ),
        "fps": (
            jr.FrictionPendulum(0.11, 2.24, 0.5),
            jr.FrictionPendulum(0.11, 2.24, 0.5, **stop),
        ),
    }


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--capacity", type=float, default=0.15)
    a = p.parse_args()
    motions = {
        "pulse": jr.near_fault_pulse("San Fernando PCD/SN"),
        "record": pacoima(),
    }
    rows = []
    for motion_name, motion in motions.items():
        for name, (free, stopped) in isolators(a.capacity).items():

            def run(base):
                return jr.behavior_map(SLENDERNESS, SIZE, base, motion, progress=False)

            maps = [run(free), run(stopped)]  # compiled
            best = [m.seconds for m in maps]
            for _ in range(a.repeats):
                best = [
                    min(b, run(base).seconds) for b, base in zip(best, (free, stopped))
                ]
            counts = [m.counts() for m in maps]
            rows.append(
                dict(
                    map=f"{motion_name}:{name}",
                    free_s=best[0],
                    stop_s=best[1],
                    ratio=best[1] / best[0],
                    free_steps=float(np.mean(maps[0].steps)),
                    stop_steps=float(np.mean(maps[1].steps)),
                    reaching=int(np.sum(maps[0].max_base_displacement >= a.capacity)),
                    free_overturned=counts[0]["overturned"],
                    stop_overturned=counts[1]["overturned"],
                    changed=int(np.sum(maps[0].outcome != maps[1].outcome)),
                    not_final=int(np.sum(maps[1].status != 0)),
                )
            )
            print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("map", "{map}"),
            ("free (s)", "{free_s:.3f}"),
            ("with stop (s)", "{stop_s:.3f}"),
            ("ratio", "{ratio:.2f}"),
            ("steps, free", "{free_steps:.0f}"),
            ("steps, with stop", "{stop_steps:.0f}"),
            ("cells reaching the stop", "{reaching}"),
            ("overturned", "{free_overturned} -> {stop_overturned}"),
            ("outcomes changed", "{changed}"),
            ("not SUCCESS", "{not_final}"),
        ],
    )
    write_results("stops", rows, md)


if __name__ == "__main__":
    main()
