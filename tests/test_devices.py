"""Maps spread their chunks over every local device: same results on two CPU devices."""

import json
import os
import subprocess
import sys

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


@pytest.fixture
def accelerator_loop(monkeypatch):
    """Chunks run on the CPU as they run on an accelerator (every lane's
    events located in one batch), on the CPU's 64 lanes."""
    monkeypatch.setattr(
        jr._layout, "loop_for", lambda platform: jr._layout.Loop(64, True)
    )


def test_an_accelerators_loop_gives_the_same_map(linear_map, accelerator_loop):
    """On a GPU the lanes that end a step have their events located together,
    not in batches of eight: the same outcomes and counts, and the same
    floats to rounding (XLA compiles the two batch shapes' arithmetic apart)."""
    again = jr.behavior_map(
        linear_map.slenderness,
        linear_map.size,
        jr.LinearIsolator(2.0, 0.35, 0.5),
        jr.near_fault_pulse("San Fernando PCD/SN"),
        chunk_size=4,
        progress=False,
    )
    for k in jr._maps._FIELDS:
        mine, theirs = getattr(again, k), getattr(linear_map, k)
        if np.issubdtype(np.asarray(theirs).dtype, np.floating):
            np.testing.assert_allclose(mine, theirs, rtol=1e-13, err_msg=k)
        else:
            np.testing.assert_array_equal(mine, theirs, err_msg=k)
