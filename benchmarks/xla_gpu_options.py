"""Behavior maps under several settings of XLA's flags, each in a fresh
process on the device JAX finds: the run time, compile time and results of
each, and whether its maps are the first setting's, bit for bit.

On a GPU, each pass of a `lax.while_loop` and each `lax.cond` reads its
predicate back to the host before the next kernel starts; XLA's command
buffers (`--xla_gpu_enable_command_buffer` with WHILE and CONDITIONAL, which
`import jaxrock` adds to `XLA_FLAGS` unless they name command buffers) run
such control flow as CUDA graphs on the device instead. The settings are
given as NAME=FLAGS (FLAGS appended to `XLA_FLAGS`; by default "host", the
loops and conditionals on the host, and "graphs", jaxrock's default), the
maps as in `device.py` (the paper's 61 x 40 grid under the San Fernando
pulse or the Pacoima Dam 164 record). Prints a Markdown table and writes
results/xla_gpu_options-<backend>.{md,json}.

    python benchmarks/xla_gpu_options.py [--repeats 3] [--tiny]
        [--maps "pulse, fixed;record, fixed"] [--timeout SECONDS]
        [--setting NAME=FLAGS ...] [--suite FILE] [--results FOLDER]
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

os.environ.setdefault("JAXROCK_CACHE", "off")  # compile times measured cold

COMMAND_BUFFERS = "--xla_gpu_enable_command_buffer"
SETTINGS = [
    f"host={COMMAND_BUFFERS}=-WHILE,-CONDITIONAL",
    f"graphs={COMMAND_BUFFERS}=+WHILE,+CONDITIONAL",
]
MAPS = "pulse, fixed;pulse, fps;record, fixed"
FIELDS = ("outcome", "max_rotation", "impacts", "steps")


def worker(maps: list[str], tiny: bool, repeats: int, folder: Path, suite) -> None:
    """Measure `maps` in this process (its `XLA_FLAGS` set by the caller):
    one JSON line a map, and its arrays to `folder`/<map>.npz."""
    import jax
    from device import _measure, scenes

    import jaxrock as jr

    devices = jax.local_devices()
    for title, _, lam, size, base, motion, _ in scenes(tiny, suite):
        if title not in maps:
            continue
        bm, compile_s, call_s = _measure(lam, size, base, motion, repeats, devices)
        np.savez(folder / f"{title}.npz", **{f: getattr(bm, f) for f in FIELDS})
        row = dict(
            map=title,
            device=devices[0].device_kind,
            compile_s=compile_s,
            run_s=bm.seconds,
            call_s=call_s,
            lane_efficiency=bm.lane_efficiency,
            failed=int(np.sum(bm.status == jr.Status.MAX_STEPS)),
        )
        print("ROW " + json.dumps(row), flush=True)


def _run_setting(name, flags, maps, a, folder: Path) -> list[dict]:
    """The rows of one setting, from a fresh process (none where it fails or
    runs past --timeout)."""
    env = dict(os.environ, XLA_FLAGS=f"{os.environ.get('XLA_FLAGS', '')} {flags}")
    command = [sys.executable, __file__, "--worker", str(folder / name)]
    command += ["--maps", ";".join(maps), "--repeats", str(a.repeats)]
    command += ["--tiny"] if a.tiny else []
    command += [] if a.suite is None else ["--suite", str(a.suite)]
    (folder / name).mkdir()
    t = time.perf_counter()
    try:
        done = subprocess.run(
            command, env=env, capture_output=True, text=True, timeout=a.timeout
        )
        out, err, failed = done.stdout, done.stderr, done.returncode != 0
    except subprocess.TimeoutExpired as e:
        out, err, failed = _text(e.stdout), _text(e.stderr), True
    rows = [json.loads(line[4:]) for line in out.splitlines() if line[:4] == "ROW "]
    if failed:
        print(f"setting {name}: failed or timed out\n{err[-3000:]}", flush=True)
    for r in rows:
        r |= dict(setting=name, flags=flags or "(none)")
    print(f"setting {name}: {time.perf_counter() - t:.0f} s", flush=True)
    return rows


def _text(b) -> str:
    return b.decode(errors="replace") if isinstance(b, bytes) else b or ""


def _same(folder: Path, first: str, name: str, title: str) -> str:
    """Whether a map of setting `name` is that of setting `first`, bit for
    bit ("yes"; else the fields that differ)."""
    a, b = (
        np.load(folder / first / f"{title}.npz"),
        np.load(folder / name / f"{title}.npz"),
    )
    differ = [f for f in FIELDS if not np.array_equal(a[f], b[f])]
    return "yes" if not differ else "no: " + ", ".join(differ)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--tiny", action="store_true")
    p.add_argument("--maps", default=MAPS)
    p.add_argument("--setting", action="append", default=None)
    p.add_argument("--timeout", type=float, default=400.0)
    p.add_argument("--results", type=Path, default=None)
    p.add_argument("--worker", type=Path, default=None)
    p.add_argument("--suite", type=Path, default=None)
    a = p.parse_args(argv)
    maps = a.maps.split(";")
    if a.worker is not None:
        return worker(maps, a.tiny, a.repeats, a.worker, a.suite)
    settings = [s.split("=", 1) for s in (a.setting or SETTINGS)]
    folder = Path(tempfile.mkdtemp(prefix="jaxrock-xla-options-"))
    rows = []
    for name, flags in settings:
        rows += _run_setting(name, flags, maps, a, folder)
    first = settings[0][0]
    base = {r["map"]: r for r in rows if r["setting"] == first}
    for r in rows:
        ref = base.get(r["map"])
        r["run_ratio"] = r["run_s"] / ref["run_s"] if ref else float("nan")
        r["same"] = _same(folder, first, r["setting"], r["map"]) if ref else "n/a"
    import jax
    from _results import markdown_table, write_results

    backend = jax.default_backend()
    device = rows[0]["device"] if rows else jax.local_devices()[0].device_kind
    head = [f"{device} ({backend}), jax {jax.__version__}", ""]
    name = f"xla_gpu_options-{backend}" + ("-tiny" if a.tiny else "")
    write_results(name, rows, head + markdown_table(rows, COLUMNS), a.results)


COLUMNS = [
    ("map", "{map}"),
    ("setting", "{setting}"),
    ("XLA flags added", "`{flags}`"),
    ("compile (s)", "{compile_s:.1f}"),
    ("run (s)", "{run_s:.4f}"),
    ("call (s)", "{call_s:.4f}"),
    ("run / first setting's", "{run_ratio:.2f}"),
    ("lane eff.", "{lane_efficiency:.0%}"),
    ("failed", "{failed}"),
    (f"same maps as the first setting ({', '.join(FIELDS)})", "{same}"),
]


if __name__ == "__main__":
    main()
