"""The persistent compilation cache: on by default in a per-user folder,
moved or turned off by JAXROCK_CACHE, and never over a cache the user
configures; the compiled chunk loops of maps kept beside it, read only when
the user's key authenticates them; JAX's entries that a full disk cut short
removed."""

import hashlib
import json
import os
import pickle
import re
import stat
import subprocess
import sys
import time
import zlib

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


@pytest.fixture
def kept(monkeypatch, tmp_path):
    """Compiled programs kept in `tmp_path / "programs"`, under a key in
    `tmp_path / "config"`."""
    folder = tmp_path / "programs"
    monkeypatch.setattr(_cache, "program_folder", lambda: folder)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    _cache._secret.cache_clear()
    yield folder
    _cache._secret.cache_clear()


def test_compiled_programs_are_kept_read_and_replaced(kept):
    lowered, lower = _twice_sin()
    x = jnp.array([0.1, 0.2, 0.3])
    first = _cache.compiled("f", "key", lower)
    (path,) = kept.glob("f-*.jaxprogram")
    again = _cache.compiled("f", "key", lower)  # loaded: not lowered again
    assert len(lowered) == 1
    np.testing.assert_array_equal(again(x), first(x))
    np.testing.assert_array_equal(again(x), 2.0 * np.sin(np.asarray(x)))
    _cache.compiled("f", "another key", lower)  # another file
    assert len(lowered) == 2 and len(list(kept.glob("f-*"))) == 2
    path.write_bytes(path.read_bytes()[:-100])  # a damaged file
    _cache.compiled("f", "key", lower)
    assert len(lowered) == 3
    _cache.compiled("f", "key", lower)  # replaced by a whole one
    assert len(lowered) == 3
    assert stat.S_IMODE(_cache.key_file().stat().st_mode) == 0o600  # the user's


class _Payload:
    """Unpickled, it creates the file `marker` (as any code could run)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _twice_sin():
    """2 sin(x) of 3 numbers: its `lower`, and a list that grows at each
    call of it."""
    lowered = []

    def lower():
        lowered.append(1)
        return jax.jit(lambda x: jnp.sin(x) * 2.0).lower(
            jax.ShapeDtypeStruct((3,), jnp.float64)
        )

    return lowered, lower


def test_a_forged_program_file_never_runs(kept, tmp_path):
    """A program file written without the user's key, whose pickle would
    create a file when read, is never unpickled: the program is compiled
    anew, gives the right values and replaces the file. The forgeries: the
    key with the sha256 of the payload (anyone can compute both), the
    HMAC line of a real file over another payload, an HMAC under another
    key."""
    marker = tmp_path / "payload-ran"
    evil = zlib.compress(pickle.dumps(_Payload(marker)))
    lowered, lower = _twice_sin()
    x = jnp.array([0.1, 0.2, 0.3])
    _cache.compiled("f", "key", lower)
    (path,) = kept.glob("f-*.jaxprogram")
    mac, content = path.read_bytes().split(b"\n", 1)
    head = content.split(b"\n", 1)[0]
    # What the key is, from public facts (versions, settings, machine).
    settings = [True, str(jax.config.jax_default_matmul_precision)]
    settings.append(os.environ.get("EQX_ON_ERROR", ""))
    key = json.dumps([_cache.code_version(), settings, _cache._machine(), "key"])
    assert head == key.encode()
    another = _cache._mac(b"another user's key".ljust(32), head + b"\n" + evil)
    forged = [
        json.dumps({"key": key, "sha256": hashlib.sha256(evil).hexdigest()}).encode()
        + b"\n"
        + evil,
        mac + b"\n" + head + b"\n" + evil,
        another.encode() + b"\n" + head + b"\n" + evil,
    ]
    for i, data in enumerate(forged):
        path.write_bytes(data)
        program = _cache.compiled("f", "key", lower)
        assert not marker.exists()
        assert len(lowered) == 2 + i  # compiled anew
        np.testing.assert_allclose(program(x), 2.0 * np.sin(np.asarray(x)), rtol=1e-15)
        assert path.read_bytes() != data  # replaced by the user's own
    _cache.compiled("f", "key", lower)  # and that one is read
    assert len(lowered) == 1 + len(forged)
    pickle.loads(zlib.decompress(evil))  # the payload is live
    assert marker.exists()


def test_a_key_that_others_can_read_is_not_used(kept):
    """A key file that others may read (they could forge files) is refused,
    with a warning naming it: programs are compiled, not kept or read."""
    lowered, lower = _twice_sin()
    _cache.compiled("f", "key", lower)
    key = _cache.key_file()
    key.chmod(0o640)
    _cache._secret.cache_clear()
    match = f"{re.escape(str(key))} can be read or written by others"
    with pytest.warns(UserWarning, match=match):
        _cache.compiled("f", "key", lower)
    _cache.compiled("f", "key", lower)
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


def _own_cache(tmp_path) -> dict:
    """The environment of a process with jaxrock's cache in `tmp_path/cache`
    and the user's key in `tmp_path/config`."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))
    }
    env["JAXROCK_CACHE"] = str(tmp_path / "cache")
    env["XDG_CONFIG_HOME"] = str(tmp_path / "config")
    return env


def test_map_loads_its_compiled_chunk_loop(tmp_path, linear_map):
    """A new process that finds the map's compiled chunk loop in jaxrock's
    folder runs it without tracing or compiling, and gets the same map to the
    bit. A forged loop (a pickle that would create a file) is not read: the
    loop is traced again and the map is the same. A loop that JAX's cache
    gives (the forged file, or none) is run but not kept: jaxlib drops the
    kernels of such code when it serializes it again."""
    env = _own_cache(tmp_path)
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
    (path,) = programs.iterdir()
    mac, head, _ = path.read_bytes().split(b"\n", 2)
    marker = tmp_path / "payload-ran"
    forged = b"\n".join([mac, head, zlib.compress(pickle.dumps(_Payload(marker)))])
    path.write_bytes(forged)
    # traced, then loaded from JAX's cache (which JAX times as a compile)
    assert run() == (1, 1, 1)
    assert not marker.exists() and path.read_bytes() == forged
    for path in programs.iterdir():
        path.unlink()
    # traced, then loaded from JAX's cache (which JAX times as a compile), and
    # not kept
    assert run() == (1, 1, 0)


ENTRY = """
import jax, jax.numpy as jnp
hits = []
jax.monitoring.register_event_listener(
    lambda event, **kw: hits.append(1) if event.endswith("cache_hits") else None
)
import jaxrock  # its programs (a conversion at import) are entries too
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
print(float(jax.jit(lambda x: jnp.sin(x) * 3.0)(1.0)), len(hits))
"""


def test_an_entry_cut_short_is_removed(tmp_path):
    """An entry of JAX's cache cut short (as on a full disk: JAX writes in
    place) would be read, warned about and compiled again in every run; the
    next run removes it before JAX reads it, so that it compiles once,
    without a warning, writes the entry whole, and the run after loads it."""
    env = _own_cache(tmp_path)
    cache = tmp_path / "cache"

    def run():
        out = subprocess.run(
            [sys.executable, "-c", ENTRY], env=env, capture_output=True, text=True
        )
        assert out.returncode == 0, out.stderr
        value, hits = out.stdout.split()
        assert float(value) == 3.0 * np.sin(1.0)
        return int(hits), out.stderr

    assert run()[0] == 0
    entries = list(cache.glob("*-cache"))
    assert entries
    for path in entries:
        written = path.stat().st_mtime
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
        os.utime(path, (written, written))  # cut short as it was written
    for path in cache.iterdir():  # and the next run a minute later
        if path.is_file():
            then = path.stat().st_mtime - 60
            os.utime(path, (then, then))
    hits, stderr = run()
    assert "Error reading persistent compilation cache" not in stderr, stderr
    assert hits == 0 and "jaxrock" not in stderr, stderr
    for path in cache.glob("*-cache"):
        zlib.decompress(path.read_bytes())  # whole
    assert run() == (len(entries), "")


def _entry(data: bytes) -> bytes:
    from jax._src.compilation_cache import compress_executable

    return compress_executable(data)


def test_an_entry_that_cannot_be_removed_is_named(monkeypatch, tmp_path):
    """A damaged entry that jaxrock cannot delete is named in a one-line
    warning, in every run until it is deleted; whole entries, entries of
    another compression and entries written in the last seconds (perhaps
    still being written) are left as they are, the last checked by a later
    run."""
    whole = tmp_path / "jit_f-1-cache"
    whole.write_bytes(_entry(b"\0\0\0\1" + bytes(range(256)) * 100))
    cut = tmp_path / "jit_g-2-cache"
    cut.write_bytes(whole.read_bytes()[:-10])
    empty = tmp_path / "jit_h-3-cache"
    empty.write_bytes(b"")
    other = tmp_path / "jit_k-4-cache"
    other.write_bytes(b"\x28\xb5\x2f\xfd" + bytes(100))  # a zstd frame's start
    old = time.time() - 60
    for path in (whole, cut, empty, other):
        os.utime(path, (old, old))
    fresh = tmp_path / "jit_m-5-cache"
    fresh.write_bytes(b"")
    unlink = type(cut).unlink

    def refused(path, missing_ok=False):
        if path.name.endswith("-cache"):
            raise PermissionError(13, "Permission denied", str(path))
        unlink(path, missing_ok=missing_ok)

    monkeypatch.setattr(type(cut), "unlink", refused)
    for _ in range(2):
        with pytest.warns(UserWarning) as caught:
            _cache.remove_damaged_entries(tmp_path)
        named = sorted(str(w.message).split()[1] for w in caught)
        assert named == [str(cut), str(empty)]
        assert all("\n" not in str(w.message) for w in caught)
    monkeypatch.setattr(type(cut), "unlink", unlink)
    _cache.remove_damaged_entries(tmp_path)
    assert sorted(p.name for p in tmp_path.glob("*-cache")) == sorted(
        [whole.name, other.name, fresh.name]
    )
    monkeypatch.setattr(_cache, "_SETTLING_S", 0.0)  # as when it has settled
    _cache.remove_damaged_entries(tmp_path)
    assert not fresh.exists() and whole.exists() and other.exists()
