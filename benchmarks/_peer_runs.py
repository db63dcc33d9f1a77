"""jaxrock and the compiled peer (benchmarks/peer.py) run side by side in one
process: compiled first, then their calls alternated, so that both see the
same machine (this shared one swings by up to 2x between minutes)."""

import os
import tempfile

import numpy as np
from _results import markdown_table


def import_peer():
    """benchmarks/peer.py, compiled cold (Numba's cache in a fresh folder, as
    jaxrock's compile times are measured without its cache folder)."""
    os.environ.setdefault("NUMBA_CACHE_DIR", tempfile.mkdtemp(prefix="peer-numba-"))
    try:
        import peer
    except ImportError as e:  # numba missing
        raise SystemExit(
            f"{e}: the peer needs numba (pip install -e '.[bench]'), or pass --no-peer"
        ) from None
    return peer


class SideBySide:
    """`run_jaxrock()` (a BehaviorMap) and `run_peer()` (peer.behavior_map's
    dict), each called once to compile, then alternated `repeats` times."""

    def __init__(self, run_jaxrock, run_peer, repeats):
        self.peer_first_s = None
        if run_peer is not None:
            first = run_peer()
            self.peer_first_s = first["seconds"]
        self.runs, self.peer_runs = [], []
        for _ in range(repeats):
            self.runs.append(run_jaxrock())
            if run_peer is not None:
                self.peer_runs.append(run_peer())

    def peer_row(self, bm):
        """The peer's fields of a results row, against jaxrock's map `bm`."""
        best = min(r["seconds"] for r in self.peer_runs)
        ours = min(r.seconds for r in self.runs)
        pm = self.peer_runs[0]
        attempts = pm["steps"] + pm["rejected_steps"]
        return dict(
            peer_s=best,
            peer_compile_s=max(self.peer_first_s - best, 0.0),
            peer_threads=int(pm["threads"]),
            jaxrock_threads=os.cpu_count(),
            peer_steps_per_analysis=float(np.mean(attempts)),
            peer_accepted_per_analysis=float(np.mean(pm["steps"])),
            peer_not_converged=int(np.sum(pm["status"] != 0)),
            outcomes_differ=int(np.sum(np.asarray(bm.outcome) != pm["outcome"])),
            ratio_best=ours / best,
            ratio_median=float(
                np.median(
                    [
                        r.seconds / p["seconds"]
                        for r, p in zip(self.runs, self.peer_runs)
                    ]
                )
            ),
        )


def peer_table(rows, key):
    """The Markdown lines of jaxrock against the peer, a row per map."""
    return markdown_table(
        rows,
        [
            (key, "{" + key + "}"),
            ("jaxrock run (s)", "{run_s:.3f}"),
            ("peer run (s)", "{peer_s:.3f}"),
            ("jaxrock / peer (median of pairs)", "{ratio_median:.2f}x"),
            ("jaxrock / peer (best runs)", "{ratio_best:.2f}x"),
            ("peer compile (s)", "{peer_compile_s:.1f}"),
            ("peer steps/analysis (accepted)", "{peer_steps_per_analysis:.0f} "
             "({peer_accepted_per_analysis:.0f})"),
            ("outcomes that differ", "{outcomes_differ}"),
            ("threads: jaxrock / peer", "{jaxrock_threads} / {peer_threads}"),
        ],
    )  # fmt: skip
