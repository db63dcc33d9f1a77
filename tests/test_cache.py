"""The persistent compilation cache: on by default in a per-user folder,
moved or turned off by JAXROCK_CACHE, and never over a cache the user
configures."""

import os
import subprocess
import sys

import pytest

PROBE = "import jaxrock, jax; print(jax.config.jax_compilation_cache_dir)"


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
        ({}, "{tmp}/home-cache/jaxrock/xla"),
        ({"JAXROCK_CACHE": "{tmp}/mine"}, "{tmp}/mine"),
        ({"JAXROCK_CACHE": "off"}, "None"),
        ({"JAX_COMPILATION_CACHE_DIR": "{tmp}/theirs"}, "{tmp}/theirs"),
    ],
    ids=["default", "moved", "off", "the user's own"],
)
def test_compilation_cache_folder(tmp_path, env, expected):
    env = {k: v.format(tmp=tmp_path) for k, v in env.items()}
    assert _cache_dir(tmp_path, **env) == expected.format(tmp=tmp_path)
