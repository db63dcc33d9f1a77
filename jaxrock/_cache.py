"""JAX's persistent compilation cache, on by default in a per-user folder, so
that a second run of a map or an analysis reuses the compiled programs of the
first."""

import os
from pathlib import Path

import jax

# The environment variable that moves the cache (a folder) or turns it off
# ("off", "0", "none" or "false").
ENVIRONMENT = "JAXROCK_CACHE"
_OFF = {"off", "0", "none", "false", "no"}


def default_folder() -> Path:
    """`$XDG_CACHE_HOME/jaxrock/xla`, else `~/.cache/jaxrock/xla`."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "jaxrock" / "xla"


def enable_compilation_cache() -> str | None:
    """Point JAX's persistent compilation cache at jaxrock's folder, unless
    the user configures JAX's cache already (`JAX_COMPILATION_CACHE_DIR` or
    `jax.config.jax_compilation_cache_dir`) or turns it off with
    `JAXROCK_CACHE=off`. `JAXROCK_CACHE=FOLDER` moves it. Returns the folder
    in use by JAX (None: no cache)."""
    setting = os.environ.get(ENVIRONMENT, "").strip()
    configured = jax.config.jax_compilation_cache_dir
    if setting.lower() in _OFF or configured:
        return configured or None
    folder = Path(setting) if setting else default_folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:  # a read-only home: no cache, and no error
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    # Programs that compile in less than this are not worth a file.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    return str(folder)
