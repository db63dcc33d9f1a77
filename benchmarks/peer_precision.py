"""Work-precision of jaxrock and the peer, side by side: the paper's 61 x 40
grid on each base (fixed, linear isolator, friction pendulum) under the
San Fernando PCD/SN pulse and under the 1971 Pacoima Dam 164 record; jaxrock
with Tsit5 and with Dopri8, and the peer (benchmarks/peer.py, Dormand-Prince
5(4) written by hand in Numba), each over a range of rtol (atol = rtol / 100).

Error: |max rotation - reference| (a fraction of alpha) over the cells that
rock in the reference; its 95th percentile is charted. The reference is
jaxrock with Dopri8 at rtol 1e-11 (atol 1e-13); the peer at rtol 1e-11 is a
second, independent one: the cells where the two disagree (outcome, or max
rotation by more than 1e-7) depend on the codes' last digits ("sensitive"),
are left out of the errors, and are counted.

Time: each map's best of --repeats runs (4 times as many where every map of
the round takes under 0.25 s), the three codes' calls alternated in one
process after a first call of each (which compiles), on as many threads
as the machine has cores. From the runs, the time each code needs to reach an
error: the least run time among its runs whose p95 error is at most that
error. Prints Markdown tables and writes
benchmarks/results/peer_precision.{json,md} and the chart
docs/peer_precision.png.

    python benchmarks/peer_precision.py [--repeats 2] [--bases fixed,linear,fps]
        [--motions pulse,record] [--rtols 1e-4,1e-5,1e-6,1e-7,1e-8,1e-9,1e-10]
"""

import argparse
import os

# Compile times are measured cold: no compiled loop from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

import diffrax  # noqa: E402
import matplotlib  # noqa: E402
import numpy as np  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from _peer_runs import import_peer  # noqa: E402
from _results import FOLDER, markdown_table, write_results  # noqa: E402
from record_maps import BASES, PEER_BASES, SIZE, SLENDERNESS, pacoima  # noqa: E402

import jaxrock as jr  # noqa: E402
from jaxrock import _ground  # noqa: E402

PULSE = "San Fernando PCD/SN"
SOLVERS = {"Tsit5": diffrax.Tsit5(), "Dopri8": diffrax.Dopri8()}
CODES = (*SOLVERS, "peer")
TARGETS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
SENSITIVE = 1e-7  # reference and peer at rtol 1e-11 disagree by more


def motions(peer):
    """Each motion: jaxrock's and the peer's."""
    amplitude, gamma, phase, frequency = _ground._TABLE_3_1[PULSE][:4]
    record = pacoima()
    return {
        "pulse": (
            jr.near_fault_pulse(PULSE),
            peer.mp_pulse(amplitude / 100, frequency, gamma, phase),
        ),
        "record": (record, peer.record(np.asarray(record.samples), float(record.dt))),
    }


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--bases", default="fixed,linear,fps")
    p.add_argument("--motions", default="pulse,record")
    p.add_argument("--rtols", default="1e-4,1e-5,1e-6,1e-7,1e-8,1e-9,1e-10")
    a = p.parse_args()
    peer = import_peer()
    lam, size = SLENDERNESS, SIZE
    rtols = [float(r) for r in a.rtols.split(",")]
    threads = os.cpu_count()
    rows, summary = [], []
    all_motions = motions(peer)
    for motion_name in a.motions.split(","):
        motion, peer_motion = all_motions[motion_name]
        for base in a.bases.split(","):

            def run(code, rtol, base=base, motion=motion, peer_motion=peer_motion):
                """(max rotation, outcome, seconds) of one map."""
                if code == "peer":
                    m = peer.behavior_map(
                        lam, size, PEER_BASES[base], peer_motion,
                        rtol=rtol, atol=rtol / 100, threads=threads,
                    )  # fmt: skip
                    return m["max_rotation"], m["outcome"], m["seconds"]
                m = jr.behavior_map(
                    lam, size, BASES[base], motion, rtol=rtol, atol=rtol / 100,
                    solver=SOLVERS[code], progress=False,
                )  # fmt: skip
                return np.asarray(m.max_rotation), np.asarray(m.outcome), m.seconds

            ref_rot, ref_out, _ = run("Dopri8", 1e-11)
            peer_rot, peer_out, _ = run("peer", 1e-11)
            sensitive = (ref_out != peer_out) | (np.abs(ref_rot - peer_rot) > SENSITIVE)
            rocks = ~sensitive & (ref_out == int(jr.Outcome.ROCKING))
            for code in CODES:
                run(code, rtols[0])  # compiles (Numba: once per base and motion)
            for rtol in rtols:
                best, rounds = {}, 0
                while rounds < _rounds(a.repeats, best):
                    rounds += 1
                    for code in CODES:
                        rot, out, seconds = run(code, rtol)
                        if code not in best or seconds < best[code][2]:
                            best[code] = (rot, out, seconds)
                for code, (rot, out, seconds) in best.items():
                    error = np.abs(rot - ref_rot)[rocks]
                    rows.append(
                        dict(
                            motion=motion_name,
                            base=base,
                            code=code,
                            rtol=rtol,
                            run_s=seconds,
                            error_p95=float(np.percentile(error, 95)),
                            error_max=float(error.max()),
                            outcomes_differ=int(np.sum((out != ref_out) & ~sensitive)),
                            sensitive_cells=int(sensitive.sum()),
                            cells_compared=int(rocks.sum()),
                        )
                    )
                    print(rows[-1], flush=True)
            summary.append(_time_to_reach(rows, motion_name, base))
    md = markdown_table(
        rows,
        [
            ("motion", "{motion}"),
            ("base", "{base}"),
            ("code", "{code}"),
            ("rtol", "{rtol:g}"),
            ("run (s)", "{run_s:.3f}"),
            ("error p95", "{error_p95:.1e}"),
            ("max", "{error_max:.1e}"),
            ("outcomes differ", "{outcomes_differ}"),
            ("sensitive cells", "{sensitive_cells}"),
            ("cells compared", "{cells_compared}"),
        ],
    )
    md += ["", _summary_table(summary)]
    write_results("peer_precision", dict(runs=rows, time_to_reach=summary), md)
    _chart(rows)


def _rounds(repeats, best):
    """Rounds of the three codes' calls: `repeats`, or 4 times as many where
    every map takes under 0.25 s (a short map's time is the noisier)."""
    if best and max(seconds for *_, seconds in best.values()) < 0.25:
        return 4 * repeats
    return repeats


def _time_to_reach(rows, motion, base):
    """Per target error: each code's least run time among its runs at most
    that error (None where no run reaches it), and jaxrock's best over the
    peer's."""
    mine = [r for r in rows if r["motion"] == motion and r["base"] == base]
    out = dict(motion=motion, base=base, targets={})
    for target in TARGETS:
        times = {}
        for code in CODES:
            ok = [
                r["run_s"]
                for r in mine
                if r["code"] == code and r["error_p95"] <= target
            ]
            times[code] = min(ok) if ok else None
        ours = [times[c] for c in SOLVERS if times[c] is not None]
        times["ratio"] = (
            min(ours) / times["peer"] if ours and times["peer"] is not None else None
        )
        out["targets"][f"{target:g}"] = times
    return out


def _summary_table(summary):
    def cell(s, target):
        t = s["targets"][f"{target:g}"]
        ours = [t[c] for c in SOLVERS if t[c] is not None]
        mine = f"{min(ours):.3f}" if ours else "-"
        theirs = "-" if t["peer"] is None else f"{t['peer']:.3f}"
        ratio = "" if t["ratio"] is None else f" ({t['ratio']:.2f}x)"
        return f"{mine} / {theirs}{ratio}"

    lines = [
        "Time to reach a p95 error of max rotation, jaxrock (the faster solver) "
        "/ peer, in s (jaxrock over the peer); - where no run reaches it:",
        "",
        "| motion | base | " + " | ".join(f"{t:g}" for t in TARGETS) + " |",
        "|---|---|" + "---|" * len(TARGETS),
    ]
    for s in summary:
        cells = " | ".join(cell(s, t) for t in TARGETS)
        lines.append(f"| {s['motion']} | {s['base']} | {cells} |")
    return "\n".join(lines)


def _chart(rows):
    panels = list(dict.fromkeys((r["motion"], r["base"]) for r in rows))
    bases = list(dict.fromkeys(b for _, b in panels))
    motions_ = list(dict.fromkeys(m for m, _ in panels))
    fig, axes = plt.subplots(
        len(motions_), len(bases), figsize=(4.2 * len(bases), 3.6 * len(motions_)),
        squeeze=False,
    )  # fmt: skip
    for (motion, base), ax in zip(
        panels, [axes[motions_.index(m), bases.index(b)] for m, b in panels]
    ):
        for code, marker in zip(CODES, "os^"):
            mine = [
                r
                for r in rows
                if r["motion"] == motion and r["base"] == base and r["code"] == code
            ]
            ax.loglog(
                [max(r["error_p95"], 1e-14) for r in mine],
                [r["run_s"] for r in mine],
                marker=marker,
                label=code if code == "peer" else f"jaxrock {code}",
            )
        ax.axvspan(1e-8, 1e-4, color="0.93", zorder=0)
        ax.set_title(f"{base}, {PULSE if motion == 'pulse' else 'Pacoima Dam 164'}")
        ax.set_xlabel("max rotation error, 95th percentile")
        ax.set_ylabel("map run time (s)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FOLDER.parents[1] / "docs" / "peer_precision.png", dpi=90)


if __name__ == "__main__":
    main()
