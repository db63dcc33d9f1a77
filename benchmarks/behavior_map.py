"""Time the paper's 2,440-cell behavior map for each base (San Fernando PCD/SN).

Prints a Markdown table and writes benchmarks/results/behavior_map.{json,md}:
compile time (first call minus the best run), run time (best of --repeats),
analyses per second, lane efficiency (useful over executed lane-steps), peak
memory of the process, and the SciPy reference (tests/reference.py, same rtol)
on a random sample of cells, extrapolated to the whole map.

A second table compares speed at the same accuracy: on the same sample, a
tight reference (SciPy at rtol 1e-12) gives the max-rotation error of the map
and of SciPy at rtol 1e-6 .. 1e-9 (relative, on the cells that rock); SciPy
at the loosest rtol whose max error is at most the map's is the like-for-like
loop, its time that at the map's rtol scaled by
its vector-field evaluations.

The peer (benchmarks/peer.py, the model written by hand in Numba: Dormand-Prince
5(4), events on its dense output, the friction pendulum's z integrated) runs
the same map in the same process, at the same rtol and atol, on as many
threads as jaxrock has cores, its calls alternated with jaxrock's: its compile
time, best run, steps per analysis, the cells whose outcome differs from
jaxrock's, its error on the sample against the tight reference, and jaxrock's
time over the peer's (the median of the paired runs' ratios, and the ratio of
the best runs). `--no-peer` leaves it out.

    python benchmarks/behavior_map.py [--repeats 3] [--sample 40] [--bases fixed,fps]
        [--no-peer]
"""

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

# Compile times are measured cold: no compiled loop from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

import jaxrock as jr  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import reference as ref  # noqa: E402
from _peer_runs import SideBySide as _SideBySide  # noqa: E402
from _peer_runs import import_peer as _peer  # noqa: E402
from _peer_runs import peer_table  # noqa: E402
from _results import write_results  # noqa: E402

PULSE = "San Fernando PCD/SN"
BASES = {
    "fixed": (jr.FixedBase(), ("fixed",)),
    "linear": (jr.LinearIsolator(2.0, 0.35, 0.5), ("linear", 2.0, 0.35, 0.5)),
    "fps": (
        jr.FrictionPendulum(0.11, 2.24, 0.5),
        ("fps", 0.11, 2.24, 0.5, 5e-4, 1.0, 0.9, 0.1, 2.0),
    ),
}
SCIPY_RTOLS = (1e-6, 1e-7, 1e-8, 1e-9)  # and the map's rtol


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--sample", type=int, default=40)
    p.add_argument("--bases", default="fixed,linear,fps")
    p.add_argument(
        "--chunk-size",
        type=lambda s: s if s == "auto" else int(s),
        default="auto",
        help="cells a chunk (default: behavior_map's own, one chunk a core)",
    )
    p.add_argument("--rtol", type=float, default=1e-8)
    p.add_argument("--no-peer", action="store_true")
    a = p.parse_args()
    peer = None if a.no_peer else _peer()
    lam = np.round(np.arange(1.0, 7.0 + 1e-9, 0.1), 10)
    size = np.round(np.arange(0.1, 4.0 + 1e-9, 0.1), 10)
    motion = jr.near_fault_pulse(PULSE)
    table = jr._ground._TABLE_3_1[PULSE]
    acc, t_end, max_step = ref.mp_pulse(table[0] / 100, table[3], table[1], table[2])
    rng = np.random.default_rng(0)
    rows = []
    for name in a.bases.split(","):
        base, ref_base = BASES[name]
        kw = dict(
            rtol=a.rtol, atol=a.rtol * 1e-2, chunk_size=a.chunk_size, progress=False
        )
        t = time.perf_counter()
        jr.behavior_map(lam, size, base, motion, **kw)
        first_s = time.perf_counter() - t
        peer_motion = (
            None
            if peer is None
            else peer.mp_pulse(table[0] / 100, table[3], table[1], table[2])
        )
        peer_kw = dict(rtol=a.rtol, atol=a.rtol * 1e-2, threads=os.cpu_count())
        side = _SideBySide(
            lambda: jr.behavior_map(lam, size, base, motion, **kw),
            None
            if peer is None
            else lambda: peer.behavior_map(lam, size, ref_base, peer_motion, **peer_kw),
            a.repeats,
        )
        runs = side.runs
        best = min(r.seconds for r in runs)
        bm = runs[0]
        cells = [
            divmod(int(c), size.size)
            for c in rng.choice(lam.size * size.size, a.sample, replace=False)
        ]

        def scipy_loop(rtol):
            """The reference on the sample: results, seconds for the map, and
            vector-field evaluations for the map."""
            t = time.perf_counter()
            out = [
                ref.simulate(
                    lam[i],
                    size[j],
                    ref_base,
                    acc,
                    t_end + 5.0,
                    max_step,
                    rtol=rtol,
                    atol=rtol * 1e-2,
                )
                for i, j in cells
            ]
            scale = lam.size * size.size / a.sample
            seconds = (time.perf_counter() - t) * scale
            return out, seconds, sum(o["evaluations"] for o in out) * scale

        out, scipy_map, scipy_evaluations = scipy_loop(a.rtol)
        agree = sum(o["outcome"] == bm.outcome[i, j] for o, (i, j) in zip(out, cells))
        tight = scipy_loop(1e-12)[0]
        rocks = [k for k, o in enumerate(tight) if o["outcome"] == 1]

        def error(rotations):
            """Max and median relative max-rotation error on the rocking cells."""
            e = [
                abs(rotations[k] - tight[k]["max_rotation"]) / tight[k]["max_rotation"]
                for k in rocks
            ]
            return float(np.max(e)), float(np.median(e))

        map_error = error([bm.max_rotation[i, j] for i, j in cells])
        rtols = sorted({*SCIPY_RTOLS, a.rtol}, reverse=True)  # loosest first
        scipy_errors = {}
        for rtol in rtols:
            o, _, evaluations = (
                (out, scipy_map, scipy_evaluations)
                if rtol == a.rtol
                else scipy_loop(rtol)
            )
            # Its time at this rtol: the time at the map's rtol scaled by the
            # evaluations (its wall time swings with the machine by up to 1.6x
            # from one loop to the next; the evaluations do not).
            seconds = scipy_map * evaluations / scipy_evaluations
            scipy_errors[rtol] = (seconds,) + error([x["max_rotation"] for x in o])
        # The loosest SciPy rtol at least as accurate as the map (max error),
        # else the tightest tried.
        like = next((r for r in rtols if scipy_errors[r][1] <= map_error[0]), rtols[-1])
        rows.append(
            dict(
                base=name,
                cells=int(bm.outcome.size),
                compile_s=first_s - best,
                run_s=best,
                analyses_per_s=bm.outcome.size / best,
                lane_efficiency=bm.lane_efficiency,
                steps=int(bm.steps.sum()),
                peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                scipy_map_s=scipy_map,
                speedup_vs_scipy=scipy_map / best,
                scipy_sample=a.sample,
                scipy_outcome_agreement=agree / a.sample,
                rocking_in_sample=len(rocks),
                map_rotation_error=map_error,
                scipy_evaluations=scipy_evaluations,
                scipy_rotation_error={f"{r:g}": e for r, e in scipy_errors.items()},
                like_rtol=like,
                like_scipy_map_s=scipy_errors[like][0],
                speedup_same_accuracy=scipy_errors[like][0] / best,
                counts=bm.counts(),
                rtol=a.rtol,
                chunk_size=a.chunk_size,
            )
        )
        if peer is not None:
            rows[-1] |= side.peer_row(bm)
            rows[-1]["peer_rotation_error"] = error(
                [
                    peer.simulate(
                        lam[i], size[j], ref_base, peer_motion, rtol=a.rtol,
                        atol=a.rtol * 1e-2,
                    )["max_rotation"]
                    for i, j in cells
                ]
            )  # fmt: skip
            rows[-1]["peer_speedup_vs_scipy"] = scipy_map / rows[-1]["peer_s"]
        print(f"{name}: {bm.summary()}", flush=True)
    header = (
        "| base | compile (s) | run (s) | analyses/s "
        "| lane eff. | SciPy map (s, extrap.) | speed-up | peak RSS (MB) |"
    )
    lines = [header, "|" + "---|" * 8]
    for r in rows:
        lines.append(
            f"| {r['base']} | {r['compile_s']:.1f} | {r['run_s']:.3f} | "
            f"{r['analyses_per_s']:.0f} | "
            f"{r['lane_efficiency']:.0%} | {r['scipy_map_s']:.0f} | "
            f"{r['speedup_vs_scipy']:.0f}x | {r['peak_rss_mb']:.0f} |"
        )
    lines += [
        "",
        "| base | map error (max / median) | SciPy error at the same rtol "
        "| SciPy as accurate as the map: rtol, map (s) | speed-up, same accuracy |",
        "|" + "---|" * 5,
    ]
    for r in rows:
        same = r["scipy_rotation_error"][f"{r['rtol']:g}"]
        lines.append(
            f"| {r['base']} | {r['map_rotation_error'][0]:.1e} / "
            f"{r['map_rotation_error'][1]:.1e} | {same[1]:.1e} / {same[2]:.1e} | "
            f"{r['like_rtol']:g}, {r['like_scipy_map_s']:.0f} | "
            f"{r['speedup_same_accuracy']:.0f}x |"
        )
    peered = [r for r in rows if "peer_s" in r]
    if peered:
        lines += [""] + peer_table(peered, "base")
        lines += [
            "",
            "| base | peer error (max / median) | map error (max / median) "
            "| peer's speed-up over SciPy |",
            "|---|---|---|---|",
        ]
        for r in peered:
            lines.append(
                f"| {r['base']} | {r['peer_rotation_error'][0]:.1e} / "
                f"{r['peer_rotation_error'][1]:.1e} | "
                f"{r['map_rotation_error'][0]:.1e} / "
                f"{r['map_rotation_error'][1]:.1e} | "
                f"{r['peer_speedup_vs_scipy']:.0f}x |"
            )
    md = "\n".join(lines)
    write_results("behavior_map", rows, md)


if __name__ == "__main__":
    main()
