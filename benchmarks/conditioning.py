"""How far the paper's maps move when their inputs move by a rounding error:
the yardstick for maps computed on another device, or by another code, which
round some operations differently.

For each of the paper's 2,440-cell maps (the San Fernando PCD/SN pulse and the
Pacoima Dam 164 record; the fixed base, the linear isolator and the friction
pendulum) it computes the map again with every slenderness, then every size,
multiplied by (1 + --relative), and counts the cells whose outcome differs,
the largest difference of max rotation where neither map overturns, and the
cells whose max rotation moves by more than 1e-6 (the measures of
`device.py --compare-cpu`).

    python benchmarks/conditioning.py [--relative 1e-15] [--maps pulse:fixed,...]

writes `results/conditioning.{md,json}`.
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


def moved(a, b) -> dict:
    """The cells of map `b` whose outcome differs from map `a`'s, and the
    largest difference of max rotation where neither overturns (each map a
    `BehaviorMap`, or a dict of its arrays)."""
    a, b = _arrays(a), _arrays(b)
    differ = a["outcome"] != b["outcome"]
    standing = (a["outcome"] != jr.Outcome.OVERTURNED) & ~differ
    delta = np.abs(a["max_rotation"] - b["max_rotation"])[standing]
    return dict(
        differ=int(differ.sum()),
        delta=float(delta.max(initial=0.0)),
        moved=int((delta > 1e-6).sum()),
    )


def _arrays(m) -> dict:
    if isinstance(m, dict):
        return m
    return {"outcome": m.outcome, "max_rotation": m.max_rotation}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--relative", type=float, default=1e-15)
    p.add_argument("--maps", default=",".join(MAPS))
    a = p.parse_args()
    factor = 1.0 + a.relative
    rows = []
    for name in a.maps.split(","):
        motion_name, base_name = name.split(":")
        motion, base = motions()[motion_name], BASES[base_name]

        def run(lam, size):
            return jr.behavior_map(lam, size, base, motion, progress=False)

        ref = run(SLENDERNESS, SIZE)
        for changed, lam, size in (
            ("slenderness", SLENDERNESS * factor, SIZE),
            ("size", SLENDERNESS, SIZE * factor),
        ):
            rows.append(
                dict(map=name, changed=changed, relative=a.relative)
                | moved(ref, run(lam, size))
            )
            print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("map", "{map}"),
            ("input changed", "{changed} x (1 + {relative:.0e})"),
            ("outcomes that differ", "{differ}"),
            ("max rotation: largest difference", "{delta:.1e}"),
            ("cells moved by > 1e-6", "{moved}"),
        ],
    )
    write_results("conditioning", rows, md)


if __name__ == "__main__":
    main()
