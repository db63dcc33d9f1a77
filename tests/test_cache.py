"""The persistent compilation cache: on by default in a per-user folder,
moved or turned off by JAXROCK_CACHE, and never over a cache the user
configures; the compiled chunk loops of maps kept beside it."""

import os
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _cache, _maps

PROBE = (
    "import jaxrock, jax; print(jax.config.jax_compilation_cache_dir, "
    "jaxrock._cache.program_folder())"
)


def _cache_dir(tmp_path, **env):
    clean = {
        k: v
        for k, v in os.environ.items()
        if k not in ("JAX_COMPILATION_CACHE_DIR", "JAXROCK_CACHE", "XDG_CACHE_HOME")
    }
    clean |= {"XDG_CACHE_HOME": str(tmp_path / "home-cache")} | env
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=clean, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


@pytest.mark.parametrize(
    "env, expected",
    [
        ({}, "{tmp}/home-cache/jaxrock/xla {tmp}/home-cache/jaxrock/xla/programs"),
        ({"JAXROCK_CACHE": "{tmp}/mine"}, "{tmp}/mine {tmp}/mine/programs"),
        ({"JAXROCK_CACHE": "off"}, "None None"),
        ({"JAX_COMPILATION_CACHE_DIR": "{tmp}/theirs"}, "{tmp}/theirs None"),
    ],
    ids=["default", "moved", "off", "the user's own"],
)
def test_compilation_cache_folder(tmp_path, env, expected):
    """The folders of JAX's compiled programs and of jaxrock's chunk loops;
    jaxrock keeps no chunk loops in a cache the user configures."""
    env = {k: v.format(tmp=tmp_path) for k, v in env.items()}
    assert _cache_dir(tmp_path, **env) == expected.format(tmp=tmp_path)


def test_compiled_programs_are_kept_read_and_replaced(monkeypatch, tmp_path):
    monkeypatch.setattr(_cache, "program_folder", lambda: tmp_path)
    lowered = []

    def lower():
        lowered.append(1)
        return jax.jit(lambda x: jnp.sin(x) * 2.0).lower(
            jax.ShapeDtypeStruct((3,), jnp.float64)
        )

    x = jnp.array([0.1, 0.2, 0.3])
    first = _cache.compiled("f", "key", lower)
    (path,) = tmp_path.glob("f-*.jaxprogram")
    again = _cache.compiled("f", "key", lower)  # loaded: not lowered again
    assert len(lowered) == 1
    np.testing.assert_array_equal(again(x), first(x))
    np.testing.assert_array_equal(again(x), 2.0 * np.sin(np.asarray(x)))
    _cache.compiled("f", "another key", lower)  # another file
    assert len(lowered) == 2 and len(list(tmp_path.glob("f-*"))) == 2
    path.write_bytes(path.read_bytes()[:-100])  # a damaged file
    _cache.compiled("f", "key", lower)
    assert len(lowered) == 3
    _cache.compiled("f", "key", lower)  # replaced by a whole one
    assert len(lowered) == 3


def test_static_key_refuses_code_outside_jaxrock():
    """A structure that names a class from elsewhere (code that could change
    unseen) is never kept."""

    class Mine(eqx.Module):
        x: jax.Array

    ours = jax.tree_util.tree_structure(jr.LinearIsolator(2.0, 0.35, 0.5))
    assert _cache.static_key(ours) == _cache.static_key(ours) is not None
    assert _cache.static_key(jax.tree_util.tree_structure(Mine(1.0))) is None


MAP = """
import sys
import jax
import numpy as np
import jaxrock as jr
events = []
jax.monitoring.register_event_time_span_listener(
    lambda event, start, end, **kw: events.append(event.rsplit("/", 1)[-1])
    if "map_chunk" in kw.get("fun_name", "") else None
)
bm = jr.behavior_map(
    [1.5, 2.5, 3.5, 5.0, 6.5], [0.3, 1.0, 2.5], jr.LinearIsolator(2.0, 0.35, 0.5),
    jr.near_fault_pulse("San Fernando PCD/SN"), chunk_size=4, progress=False,
)
np.savez(sys.argv[1], **{k: getattr(bm, k) for k in sys.argv[2:]})
print(events.count("jaxpr_trace_duration"), events.count("backend_compile_duration"))
"""


def test_map_loads_its_compiled_chunk_loop(tmp_path, linear_map):
    """A new process that finds the map's compiled chunk loop in jaxrock's
    folder runs it without tracing or compiling, and gets the same map to the
    bit. A loop that JAX's cache gives (the folder's `programs/` deleted) is
    run but not kept: jaxlib drops the kernels of such code when it
    serializes it again."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))
    }
    env["JAXROCK_CACHE"] = str(tmp_path / "cache")
    programs = tmp_path / "cache" / "programs"

    def run():
        out = subprocess.run(
            [sys.executable, "-c", MAP, str(tmp_path / "map.npz"), *_maps._FIELDS],
            env=env,
            capture_output=True,
            text=True,
        )
        assert out.returncode == 0, out.stderr
        saved = np.load(tmp_path / "map.npz")
        for k in _maps._FIELDS:
            np.testing.assert_array_equal(saved[k], getattr(linear_map, k))
        traces, compiles = map(int, out.stdout.split())
        return traces, compiles, len(list(programs.glob("map_chunk-*.jaxprogram")))

    assert run() == (1, 1, 1)  # traced, compiled and kept
    assert run() == (0, 0, 1)  # loaded
    for path in programs.iterdir():
        path.unlink()
    # traced, then loaded from JAX's cache (which JAX times as a compile), and
    # not kept
    assert run() == (1, 1, 0)
