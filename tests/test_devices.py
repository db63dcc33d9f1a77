"""Maps spread their chunks over every local device: same results on two CPU devices."""

import json
import os
import socket
import subprocess
import sys

import jax
import numpy as np
import pytest

import jaxrock as jr

SCRIPT = """
import json, numpy as np, jax, jaxrock as jr
bm = jr.behavior_map([2.5, 4.0, 5.5], [0.4, 1.0, 2.0],
                     jr.LinearIsolator(2.0, 0.35, 0.5),
                     jr.near_fault_pulse("San Fernando PCD/SN"), chunk_size=2)
print(json.dumps(dict(devices=len(jax.local_devices()), outcome=bm.outcome.tolist(),
                      rotation=bm.max_rotation.tolist())))
"""


@pytest.fixture(scope="module")
def one():
    """The map of the scripts below, on this process's one device."""
    return jr.behavior_map(
        [2.5, 4.0, 5.5],
        [0.4, 1.0, 2.0],
        jr.LinearIsolator(2.0, 0.35, 0.5),
        jr.near_fault_pulse("San Fernando PCD/SN"),
        chunk_size=2,
    )


def test_two_cpu_devices_give_the_same_map(one):
    flags = (
        os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    )
    env = dict(os.environ, XLA_FLAGS=flags.strip())
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    )
    two = json.loads(out.stdout.strip().splitlines()[-1])
    assert two["devices"] == 2
    np.testing.assert_array_equal(np.array(two["outcome"]), one.outcome)
    np.testing.assert_allclose(np.array(two["rotation"]), one.max_rotation, rtol=1e-12)


MULTIHOST = """
import json, sys, jax
jax.distributed.initialize(coordinator_address=sys.argv[1], num_processes=2,
                           process_id=int(sys.argv[2]))
import jaxrock as jr
from jaxrock import _maps
computed = []
compute = _maps._map_chunk
# chunks of cells (a[-2] is the pilot flag; each process runs its own pilots)
_maps._map_chunk = lambda *a: computed.append(not a[-2]) or compute(*a)
bm = jr.behavior_map([2.5, 4.0, 5.5], [0.4, 1.0, 2.0],
                     jr.LinearIsolator(2.0, 0.35, 0.5),
                     jr.near_fault_pulse("San Fernando PCD/SN"), chunk_size=2,
                     store=sys.argv[3], progress=False)
print(json.dumps(dict(process=jax.process_index(), outcome=bm.outcome.tolist(),
                      rotation=bm.max_rotation.tolist(), computed=sum(computed))))
jax.distributed.shutdown()
"""


def test_two_processes_share_a_map_through_the_store(tmp_path, one):
    # Two processes on this machine stand in for two hosts (jax.distributed).
    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", MULTIHOST, f"localhost:{port}", str(i), tmp_path],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    outs = [p.communicate(timeout=600) for p in procs]
    assert all(p.returncode == 0 for p in procs), [err[-2000:] for _, err in outs]
    results = [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]
    # Chunks 0, 2, 4 fall to process 0 and 1, 3 to process 1.
    assert sorted((r["process"], r["computed"]) for r in results) == [(0, 3), (1, 2)]
    for r in results:  # every process holds the whole map
        np.testing.assert_array_equal(np.array(r["outcome"]), one.outcome)
        np.testing.assert_allclose(
            np.array(r["rotation"]), one.max_rotation, rtol=1e-12
        )
    assert len(list(tmp_path.glob("chunk_*.npz"))) == 5  # 9 cells, chunks of 2


def test_several_processes_need_a_store(monkeypatch):
    monkeypatch.setattr(jax, "process_count", lambda: 2)
    with pytest.raises(ValueError, match="store"):
        jr.behavior_map(
            [4.0], [1.0], jr.FixedBase(), jr.near_fault_pulse("Tabas TAB/SP")
        )
