"""Work-precision under a record: the paper's 61 x 40 grid under the 1971
Pacoima Dam 164 record, per base, for Tsit5 and Dopri8 over a range of rtol
(atol = rtol / 100): run time against the error of max rotation.

The reference is the map with Dopri8 at rtol 1e-11 (atol 1e-13). A second
one, Tsit5 at rtol 1e-10 (atol 1e-12), flags the cells whose response depends
on the solver's last digits ("sensitive": their outcomes differ or their max
rotations differ by more than 1e-3): they are left out of the errors and
counted. The errors are over the other cells that rock in the reference:
the 95th and 99th percentiles and the largest |max rotation - reference|
(a fraction of alpha), and the cells whose outcome differs. Run time is the
best of --repeats runs after a first call (which compiles). Prints a
Markdown table and writes benchmarks/results/record_precision.{json,md} and
a chart, docs/record_precision.png.

    python benchmarks/record_precision.py [--repeats 2] [--bases fixed,linear,fps]
        [--rtols 1e-6,1e-7,1e-8,1e-9]
"""

import argparse

import diffrax
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from _results import FOLDER, markdown_table, write_results  # noqa: E402

# The grid's bases and record, and a cold cache (JAXROCK_CACHE=off), as there.
from record_maps import BASES, SIZE, SLENDERNESS, pacoima  # noqa: E402

import jaxrock as jr  # noqa: E402

SOLVERS = {"Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8()}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--bases", default="fixed,linear,fps")
    p.add_argument("--rtols", default="1e-6,1e-7,1e-8,1e-9")
    a = p.parse_args()
    lam, size = SLENDERNESS, SIZE
    record = pacoima()
    rtols = [float(r) for r in a.rtols.split(",")]
    rows = []
    for name in a.bases.split(","):

        def run(solver, rtol, name=name):
            return jr.behavior_map(
                lam,
                size,
                BASES[name],
                record,
                rtol=rtol,
                atol=rtol / 100,
                solver=solver,
                progress=False,
            )

        ref = run(diffrax.Dopri8(), 1e-11)
        other = run(diffrax.Tsit5(), 1e-10)
        sensitive = (ref.outcome != other.outcome) | (
            np.abs(ref.max_rotation - other.max_rotation) > 1e-3
        )
        rocks = ~sensitive & (ref.outcome == jr.Outcome.ROCKING)
        for solver_name, solver in SOLVERS.items():
            for rtol in rtols:
                run(solver, rtol)  # compiles (once per solver and base)
                bm = min(
                    (run(solver, rtol) for _ in range(a.repeats)),
                    key=lambda m: m.seconds,
                )
                error = np.abs(bm.max_rotation - ref.max_rotation)[rocks]
                rows.append(
                    dict(
                        base=name,
                        solver=solver_name,
                        rtol=rtol,
                        run_s=bm.seconds,
                        steps_per_analysis=float(np.mean(bm.steps)),
                        error_p95=float(np.percentile(error, 95)),
                        error_p99=float(np.percentile(error, 99)),
                        error_max=float(error.max()),
                        outcomes_differ=int(
                            np.sum((bm.outcome != ref.outcome) & ~sensitive)
                        ),
                        sensitive_cells=int(sensitive.sum()),
                        cells_compared=int(rocks.sum()),
                    )
                )
                print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("base", "{base}"),
            ("solver", "{solver}"),
            ("rtol", "{rtol:g}"),
            ("run (s)", "{run_s:.2f}"),
            ("steps/analysis", "{steps_per_analysis:.0f}"),
            ("error p95", "{error_p95:.1e}"),
            ("p99", "{error_p99:.1e}"),
            ("max", "{error_max:.1e}"),
            ("outcomes differ", "{outcomes_differ}"),
            ("sensitive cells", "{sensitive_cells}"),
        ],
    )
    write_results("record_precision", rows, md)
    bases = list(dict.fromkeys(r["base"] for r in rows))
    fig, axes = plt.subplots(1, len(bases), figsize=(4.2 * len(bases), 3.6))
    for ax, name in zip(np.atleast_1d(axes), bases):
        for solver_name, marker in zip(SOLVERS, "os"):
            mine = [r for r in rows if r["base"] == name and r["solver"] == solver_name]
            ax.loglog(
                [r["error_p95"] for r in mine],
                [r["run_s"] for r in mine],
                marker=marker,
                label=solver_name,
            )
            for r in mine:
                ax.annotate(f"{r['rtol']:g}", (r["error_p95"], r["run_s"]), fontsize=7)
        ax.set_title(f"{name}, Pacoima Dam 164")
        ax.set_xlabel("max rotation error, 95th percentile")
        ax.set_ylabel("map run time (s)")
        ax.legend()
    fig.tight_layout()
    fig.savefig(FOLDER.parents[1] / "docs" / "record_precision.png", dpi=90)


if __name__ == "__main__":
    main()
