"""What checking sliding costs, and where blocks slide: the paper's
2,440-cell maps under the San Fernando PCD/SN pulse and the Pacoima Dam 164
record on the fixed base, the linear isolator and the friction pendulum,
without a friction and with mu = 0.3, 0.5 and 0.7 (`behavior_map(...,
friction=mu)`).

For each map: the best of `--repeats` runs of each (compiled first, calls
alternated), steps per analysis, and the cells whose block would slide
(`Status.SLIDING`) with, among them, those that overturn without sliding.

    python benchmarks/sliding.py [--repeats 3] [--maps pulse:fixed,record:fps]

writes `results/sliding.{md,json}`.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import markdown_table, write_results  # noqa: E402
from record_maps import BASES, SIZE, SLENDERNESS  # noqa: E402
from window import MAPS, motions  # noqa: E402

import jaxrock as jr  # noqa: E402

FRICTIONS = (None, 0.3, 0.5, 0.7)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--maps", default=",".join(MAPS))
    a = p.parse_args()
    rows = []
    for name in a.maps.split(","):
        motion_name, base_name = name.split(":")
        motion, base = motions()[motion_name], BASES[base_name]

        def run(mu):
            return jr.behavior_map(
                SLENDERNESS, SIZE, base, motion, friction=mu, progress=False
            )

        maps = {mu: run(mu) for mu in FRICTIONS}  # compiled
        best = {mu: m.seconds for mu, m in maps.items()}
        for _ in range(a.repeats):
            for mu in FRICTIONS:
                best[mu] = min(best[mu], run(mu).seconds)
        plain = maps[None]
        for mu in FRICTIONS[1:]:
            sliding = maps[mu].status == jr.Status.SLIDING
            rows.append(
                dict(
                    map=name,
                    friction=mu,
                    seconds=best[mu],
                    plain_s=best[None],
                    ratio=best[mu] / best[None],
                    steps=float(np.mean(maps[mu].steps)),
                    plain_steps=float(np.mean(plain.steps)),
                    sliding=int(np.sum(sliding)),
                    sliding_overturned=int(
                        np.sum(sliding & (plain.outcome == jr.Outcome.OVERTURNED))
                    ),
                    cells=int(sliding.size),
                )
            )
            print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("map", "{map}"),
            ("mu", "{friction:g}"),
            ("with mu (s)", "{seconds:.3f}"),
            ("without (s)", "{plain_s:.3f}"),
            ("ratio", "{ratio:.2f}"),
            ("steps, with mu", "{steps:.0f}"),
            ("steps, without", "{plain_steps:.0f}"),
            ("cells sliding", "{sliding} of {cells}"),
            ("of them overturned", "{sliding_overturned}"),
        ],
    )
    write_results("sliding", rows, md)


if __name__ == "__main__":
    main()
