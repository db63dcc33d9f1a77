"""`benchmarks/device.py` at a tiny size on the CPU: every map runs, and the
maps it compares with a second process's CPU maps agree to the bit."""

import json
import os
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def test_device_benchmark_runs_and_matches_the_cpu_maps(tmp_path):
    command = [sys.executable, "device.py", "--tiny", "--repeats", "0"]
    command += ["--compare-cpu", "--lanes", "32", "--results", str(tmp_path)]
    subprocess.run(
        command, cwd=BENCHMARKS, env=dict(os.environ), check=True, timeout=1200
    )
    results = json.loads((tmp_path / "device-cpu-tiny.json").read_text())
    assert results["info"]["backend"] == "cpu"
    assert results["info"]["lane_width"] == 64
    rows = {r["map"]: r for r in results["rows"]}
    # Pulse and record maps on three bases, a suite, two larger maps, a sweep.
    assert len(rows) == 10
    assert rows["64 cells, fixed, lanes"]["lanes"] == 32
    for row in rows.values():
        assert row["not_success"] == 0, row["map"]
        assert 0 < row["lane_efficiency"] <= 1
        assert row["analyses_per_s"] > 0
    compared = [r for r in rows.values() if "cpu_outcomes_differ" in r]
    assert len(compared) == 6
    for row in compared:
        assert row["cpu_outcomes_differ"] == 0, row["map"]
        assert row["cpu_max_rotation_delta"] == 0.0, row["map"]
    assert (tmp_path / "device-cpu-tiny.md").read_text().startswith("cpu (cpu)")


def test_xla_options_benchmark_runs_each_setting_and_compares_its_maps(tmp_path):
    """Each setting in its own process, its flags in its `XLA_FLAGS`; on the
    CPU, which ignores the GPU's command buffers, the maps are identical."""
    command = [sys.executable, "xla_gpu_options.py", "--tiny", "--repeats", "0"]
    command += ["--maps", "pulse, fixed", "--results", str(tmp_path)]
    subprocess.run(
        command, cwd=BENCHMARKS, env=dict(os.environ), check=True, timeout=1200
    )
    rows = json.loads((tmp_path / "xla_gpu_options-cpu-tiny.json").read_text())
    assert [(r["setting"], r["map"]) for r in rows] == [
        ("host", "pulse, fixed"),
        ("graphs", "pulse, fixed"),
    ]
    assert rows[1]["flags"].endswith("=+WHILE,+CONDITIONAL")
    for row in rows:
        assert row["same"] == "yes" and row["failed"] == 0
        assert row["run_s"] > 0 and row["run_ratio"] > 0
