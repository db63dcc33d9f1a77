"""JAX's persistent compilation cache, on by default in a per-user folder,
so that a second run of a map or an analysis reuses the compiled programs of
the first; and in its `programs/` folder the compiled chunk loops of maps,
whole, so that a second run of a map skips tracing and lowering as well."""

import functools
import hashlib
import importlib.metadata
import io
import json
import os
import pickle
import platform
import threading
import zlib
from collections.abc import Callable
from pathlib import Path

import jax
from jax.experimental import serialize_executable

from ._misc import turned_off

# The environment variable that moves the cache (a folder) or turns it off
# (`turned_off`).
ENVIRONMENT = "JAXROCK_CACHE"
# Where a kept program's code may come from: it is kept only when its
# static structure names no class or function from elsewhere (a user's own
# isolator or solver: its code could change unseen), and these packages'
# versions (jaxrock's: its source files) are part of its key.
_PACKAGES = ("jax", "jaxlib", "equinox", "diffrax", "lineax", "optimistix", "numpy")


def default_folder() -> Path:
    """`$XDG_CACHE_HOME/jaxrock/xla`, else `~/.cache/jaxrock/xla`."""
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "jaxrock" / "xla"


# The folder `enable_compilation_cache` gave JAX (None: none, or the user's).
_FOLDER: str | None = None


def enable_compilation_cache() -> str | None:
    """Point JAX's persistent compilation cache at jaxrock's folder, unless
    the user configures JAX's cache already (`JAX_COMPILATION_CACHE_DIR` or
    `jax.config.jax_compilation_cache_dir`) or turns it off with
    `JAXROCK_CACHE=off`. `JAXROCK_CACHE=FOLDER` moves it. Returns the folder
    in use by JAX (None: no cache)."""
    global _FOLDER
    setting = os.environ.get(ENVIRONMENT, "").strip()
    configured = jax.config.jax_compilation_cache_dir
    if turned_off(setting) or configured:
        return configured or None
    folder = Path(setting) if setting else default_folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:  # a read-only home: no cache, and no error
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    # Programs that compile in less than this are not worth a file.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    _FOLDER = str(folder)
    return _FOLDER


def program_folder() -> Path | None:
    """`programs/` in jaxrock's cache folder, where compiled chunk loops are
    kept; None when JAX's cache is not jaxrock's (turned off, or the user's
    own, which jaxrock leaves as it is)."""
    if _FOLDER is None or jax.config.jax_compilation_cache_dir != _FOLDER:
        return None
    return Path(_FOLDER) / "programs"


@functools.cache
def code_version() -> str:
    """What a kept program depends on besides its arguments: the versions of
    `_PACKAGES`, a digest of jaxrock's source files (an edited checkout is
    another version) and the platform."""
    digest = hashlib.sha256()
    root = Path(__file__).parent
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    versions = {p: importlib.metadata.version(p) for p in _PACKAGES}
    return json.dumps(
        versions | {"jaxrock": digest.hexdigest(), "platform": jax.default_backend()}
    )


class _Globals(pickle.Unpickler):
    """Reads a pickle back, recording the modules of the classes and
    functions it names."""

    def __init__(self, data: bytes):
        super().__init__(io.BytesIO(data))
        self.modules: set[str] = set()

    def find_class(self, module, name):
        self.modules.add(module)
        return super().find_class(module, name)


def static_key(tree) -> str | None:
    """A digest of `tree` (e.g. a pytree structure with its static fields),
    by pickle; None when it cannot be pickled or names code outside jaxrock
    and `_PACKAGES` (its changes would go unseen)."""
    try:
        data = pickle.dumps(tree)
        names = _Globals(data)
        names.load()
    except Exception:  # anything unpicklable: not kept
        return None
    allowed = {"builtins", "jaxrock", *_PACKAGES}
    if any(m.split(".")[0] not in allowed for m in names.modules):
        return None
    return _digest(data)


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# Hits of JAX's persistent cache in each thread (`_cache_hits`).
_HITS = threading.local()


def _count_hit(event: str, **kwargs) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _HITS.count = _cache_hits() + 1


@functools.cache
def _listen() -> None:
    jax.monitoring.register_event_listener(_count_hit)


def _cache_hits() -> int:
    """Executables this thread has loaded from JAX's persistent cache since
    the first call."""
    _listen()
    return getattr(_HITS, "count", 0)


@functools.cache
def _machine() -> list[str]:
    """What compiled code depends on besides the program and the platform
    (`code_version`): the device, XLA's flags and the processor (its
    instruction set extensions, which XLA's CPU code uses)."""
    device = jax.local_devices()[0]
    flags = ""
    if platform.system() == "Linux":
        try:
            with open("/proc/cpuinfo") as info:
                flags = next((x for x in info if x.startswith("flags")), "")
        except OSError:
            pass
    return [
        device.device_kind,
        device.client.platform_version,
        os.environ.get("XLA_FLAGS", ""),
        platform.machine(),
        platform.processor(),
        _digest(flags.encode()),
    ]


def compiled(name: str, key: str | None, lower: Callable[[], jax.stages.Lowered]):
    """The program `lower()` gives, compiled (`jax.stages.Compiled`), kept
    in `program_folder()` and read back by later processes.

    Its file, `NAME-DIGEST.jaxprogram`, is keyed by `key` (what the program
    depends on besides code: its static structure, shapes, ...), by
    `code_version()`, by the settings that change what tracing makes
    (float64, matmul precision, Equinox's error mode) and by the machine
    (`_machine`). A kept program is loaded instead of calling `lower` and
    compiling; a file that is damaged or holds another key is replaced.
    Without a folder or a key (None: not to be kept), `lower().compile()`."""
    folder = program_folder()
    if folder is None or key is None:
        return lower().compile()
    settings = [
        jax.config.jax_enable_x64,
        str(jax.config.jax_default_matmul_precision),
        os.environ.get("EQX_ON_ERROR", ""),
    ]
    key = json.dumps([code_version(), settings, _machine(), key])
    path = folder / f"{name}-{_digest(key.encode())[:32]}.jaxprogram"
    try:
        head, payload = path.read_bytes().split(b"\n", 1)
        if json.loads(head) == {"key": key, "sha256": _digest(payload)}:
            saved = pickle.loads(zlib.decompress(payload))
            return serialize_executable.deserialize_and_load(*saved)
    except Exception:  # missing or damaged: compile again
        pass
    hits = _cache_hits()
    program = lower().compile()
    if _cache_hits() != hits:
        # Loaded from JAX's cache: jaxlib serializes such code without its
        # kernels (it fails when run), so only a program compiled here is kept.
        return program
    partial = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}")
    try:
        saved = serialize_executable.serialize(program)
        payload = zlib.compress(pickle.dumps(saved), 1)
        head = json.dumps({"key": key, "sha256": _digest(payload)})
        folder.mkdir(parents=True, exist_ok=True)
        partial.write_bytes(head.encode() + b"\n" + payload)
        os.replace(partial, path)  # whole files only, also between processes
    except Exception:  # a read-only folder...: the program is used, not kept
        partial.unlink(missing_ok=True)
    return program
