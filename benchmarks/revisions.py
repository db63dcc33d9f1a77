"""Two revisions of jaxrock side by side: the paper's maps (2,440 cells) under
the San Fernando PCD/SN pulse and the Pacoima Dam 164 record on the fixed
base, the linear isolator and the friction pendulum, timed by the checked-out
code (or the revision `--this`) and by another git revision (a worktree of
it), in fresh processes run in turn (other, this, other, this, ...), each
with an empty cache folder.

For each map: the compile time (the first call less the best run) and the
best of `--repeats` runs of each process; the ratios this / other pair by
pair, and their median. Both revisions' maps are compared to the bit.

    python benchmarks/revisions.py --against HEAD~1 [--this REV] [--pairs 3]
        [--repeats 5] [--maps pulse:fixed,record:fps] [--after 5]

writes `results/revisions.{md,json}`.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import markdown_table, write_results  # noqa: E402

MAPS = [f"{m}:{b}" for m in ("pulse", "record") for b in ("fixed", "linear", "fps")]


def _worker(names, repeats, after, out):
    """Time the maps `names` in this process (jaxrock from PYTHONPATH)."""
    from record_maps import BASES, SIZE, SLENDERNESS, pacoima

    import jaxrock as jr

    lam, size = SLENDERNESS, SIZE
    motions = {"pulse": jr.near_fault_pulse("San Fernando PCD/SN"), "record": pacoima()}
    bases = BASES
    rows, arrays = {}, {}
    for name in names:
        motion, base = name.split(":")

        duration = None if after is None else float(motions[motion].end_time) + after

        def run():
            return jr.behavior_map(
                lam,
                size,
                bases[base],
                motions[motion],
                duration=duration,
                progress=False,
            )

        t = time.perf_counter()
        first = run()
        first_s = time.perf_counter() - t
        best = min(run().seconds for _ in range(repeats))
        rows[name] = dict(compile_s=max(first_s - best, 0.0), run_s=best)
        arrays[name] = np.stack([first.max_rotation, first.steps.astype(float)])
    np.savez(out + ".npz", **{k.replace(":", "_"): v for k, v in arrays.items()})
    Path(out + ".json").write_text(json.dumps(rows))


def _run(path, names, repeats, after, out):
    """A fresh worker process with jaxrock from `path`."""
    env = dict(os.environ, PYTHONPATH=str(path), JAX_PLATFORMS="cpu")
    with tempfile.TemporaryDirectory() as cache:
        env["JAXROCK_CACHE"] = cache
        subprocess.run(
            [sys.executable, __file__, "--worker", ",".join(names), out]
            + ["--repeats", str(repeats)]
            + ([] if after is None else ["--after", str(after)]),
            env=env,
            check=True,
        )
    return json.loads(Path(out + ".json").read_text()), np.load(out + ".npz")


def _short(revision: str) -> str:
    return subprocess.run(
        ["git", "rev-parse", "--short", revision],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()


def _worktree(path: Path, revision: str) -> Path:
    """A checkout of `revision` at `path` (a git worktree)."""
    subprocess.run(
        ["git", "worktree", "add", "--detach", "-q", str(path), revision],
        cwd=ROOT,
        check=True,
    )
    return path


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--against", default="HEAD~1", help="the other git revision")
    p.add_argument("--this", help="a revision instead of the working tree")
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--maps", default=",".join(MAPS))
    p.add_argument(
        "--after",
        type=float,
        help="a window that ends this long after the excitation (s); default: "
        "each revision's own default",
    )
    p.add_argument("--worker", help=argparse.SUPPRESS)
    a, rest = p.parse_known_args()
    if a.worker:
        return _worker(a.worker.split(","), a.repeats, a.after, rest[0])
    names = a.maps.split(",")
    revision = _short(a.against)
    this_name = "this" if a.this is None else _short(a.this)
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"other": _worktree(Path(tmp) / "other", revision)}
        trees["this"] = (
            ROOT if a.this is None else _worktree(Path(tmp) / "this", a.this)
        )
        try:
            runs = {"other": [], "this": []}
            for k in range(a.pairs):
                for who in ("other", "this"):
                    out = str(Path(tmp) / f"{who}{k}")
                    runs[who].append(_run(trees[who], names, a.repeats, a.after, out))
        finally:
            for who, tree in trees.items():
                if tree != ROOT:
                    subprocess.run(
                        ["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT
                    )
    rows = []
    for name in names:
        pairs = list(zip(runs["other"], runs["this"]))
        same = all(
            np.array_equal(o[1][name.replace(":", "_")], t[1][name.replace(":", "_")])
            for o, t in pairs
        )
        row = dict(map=name, identical=same)
        for what in ("run_s", "compile_s"):
            other_s = [o[0][name][what] for o, _ in pairs]
            this_s = [t[0][name][what] for _, t in pairs]
            row[f"other_{what}"] = float(np.median(other_s))
            row[f"this_{what}"] = float(np.median(this_s))
            row[f"{what}_ratio"] = float(
                np.median([t / o for t, o in zip(this_s, other_s)])
            )
        rows.append(row)
    md = [
        f"{this_name} against {revision} ({a.pairs} pairs of fresh processes, "
        f"best of {a.repeats} runs each; medians"
        + ("" if a.after is None else f"; windows end {a.after:g} s after the motion")
        + "):",
        "",
        *markdown_table(
            rows,
            [
                ("map", "{map}"),
                (f"run (s), {revision}", "{other_run_s:.3f}"),
                (f"run (s), {this_name}", "{this_run_s:.3f}"),
                ("run ratio", "{run_s_ratio:.3f}"),
                (f"compile (s), {revision}", "{other_compile_s:.1f}"),
                (f"compile (s), {this_name}", "{this_compile_s:.1f}"),
                ("compile ratio", "{compile_s_ratio:.3f}"),
                ("identical", "{identical}"),
            ],
        ),
    ]
    result = dict(against=revision, this=this_name, after=a.after, rows=rows)
    write_results("revisions", result, md)


if __name__ == "__main__":
    main()
