"""JAX's persistent compilation cache, on by default in a per-user folder,
so that a second run of a map or an analysis reuses the compiled programs of
the first; and in its `programs/` folder the compiled chunk loops of maps,
whole, so that a second run of a map skips tracing and lowering as well.

jaxlib serializes a whole compiled program as a pickle, and unpickling can
run any code: each kept file carries an HMAC of its contents under a key only
the user can read (`key_file`), checked before anything in the file is read.
JAX's own entries beside them are compiled machine code that JAX loads as it
finds them: a cache folder trusts whoever can write to it."""

import functools
import hashlib
import hmac
import importlib.metadata
import io
import json
import os
import pickle
import platform
import secrets
import tempfile
import threading
import time
import warnings
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
    # Every program, however small: JAX looks each one up in the folder
    # anyway, and loading one of the tiny programs that operations on
    # concrete arrays compile (about 50 ms each, a dozen in a `simulate`)
    # takes a few ms.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    _FOLDER = str(folder)
    remove_damaged_entries(folder)
    return _FOLDER


# Entries younger than this (s) may still be being written by another
# process: a later run checks them.
_SETTLING_S = 5.0


def remove_damaged_entries(folder: Path) -> None:
    """Deletes the entries of JAX's cache in `folder` that JAX cannot read:
    cut short by a full disk or a killed process (JAX writes an entry in
    place, and one it cannot read it compiles again in every run, never
    replacing it). Each entry is read once, by the first run after it is
    written: the check's time is that of a file `jaxrock-checked-FORMAT` in
    the folder (none that this user can write: no check). Entries of another
    compression than this JAX's are left alone. An entry that cannot be
    deleted (another user's) is named in a warning, in every run, until it
    is."""
    try:
        from jax._src.compilation_cache import (
            compress_executable,
            decompress_executable,
        )
    except ImportError:  # another JAX: its entries are left as they are
        return
    magic = compress_executable(b"")[:2]
    stamp = folder / f"jaxrock-checked-{magic.hex()}"
    try:
        since = stamp.stat().st_mtime
    except FileNotFoundError:
        since = 0.0
    except OSError:
        return
    until = time.time() - _SETTLING_S
    try:
        stamp.touch()
    except OSError:  # a folder this user cannot write: no check
        return
    try:
        with os.scandir(folder) as found:
            entries = [
                e
                for e in found
                if e.name.endswith("-cache") and e.is_file(follow_symlinks=False)
            ]
    except OSError:
        return
    damaged = []
    for entry in entries:
        try:
            written = entry.stat(follow_symlinks=False).st_mtime
            if not since <= written < until:
                continue
            data = Path(entry.path).read_bytes()
        except OSError:  # gone, or not this user's to read
            continue
        if len(data) < len(magic):
            damaged.append((written, Path(entry.path)))
        elif data.startswith(magic):
            try:
                decompress_executable(data)
            except Exception:  # what JAX's read would raise
                damaged.append((written, Path(entry.path)))
    for written, path in damaged:
        try:
            path.unlink(missing_ok=True)  # or another process did
            path.with_name(path.name.removesuffix("-cache") + "-atime").unlink(
                missing_ok=True
            )
        except OSError:
            warnings.warn(
                f"jaxrock: {path} is a damaged entry of JAX's compilation cache "
                "(cut short, as on a full disk), which JAX compiles again in "
                "every run; delete it"
            )
            until = min(until, written)
    try:
        os.utime(stamp, (until, until))
    except OSError:
        pass


def key_file() -> Path:
    """`$XDG_CONFIG_HOME/jaxrock/cache-key`, else
    `~/.config/jaxrock/cache-key`: the key that authenticates kept programs,
    in the user's own folder, never in the cache folder (which others may
    share)."""
    base = os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config"
    return Path(base) / "jaxrock" / "cache-key"


_KEY_BYTES = 32


@functools.cache
def _secret() -> bytes | None:
    """The user's key for kept programs (`key_file`): 32 random bytes,
    readable by the user alone, made on first use. None (no program is kept)
    where it cannot be made or read, or is not the user's alone (a warning
    names the file)."""
    path = key_file()
    try:
        return _read_secret(path)
    except FileNotFoundError:
        pass
    except OSError:
        return None
    partial = None
    try:
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        fd, partial = tempfile.mkstemp(dir=path.parent, prefix=".cache-key.")
        with os.fdopen(fd, "wb") as file:  # mkstemp: mode 0600
            file.write(secrets.token_bytes(_KEY_BYTES))
        try:
            os.link(partial, path)  # a whole key, never over another process's
        except FileExistsError:
            pass
        return _read_secret(path)
    except OSError:  # a read-only home...: programs are not kept
        return None
    finally:
        if partial is not None:
            Path(partial).unlink(missing_ok=True)


def _read_secret(path: Path) -> bytes | None:
    """The key in `path`; None, with a warning, if others may read or write
    it or it is not a key."""
    with open(path, "rb") as file:
        info = os.fstat(file.fileno())
        secret = file.read(_KEY_BYTES + 1)
    if os.name == "posix" and (info.st_uid != os.getuid() or info.st_mode & 0o077):
        problem = "can be read or written by others"
    elif len(secret) != _KEY_BYTES:
        problem = f"is not a key of {_KEY_BYTES} bytes"
    else:
        return secret
    warnings.warn(
        f"jaxrock: {path} {problem}: compiled map loops are not kept or read; "
        "delete it (jaxrock makes a new one)",
        stacklevel=3,
    )
    return None


def _mac(secret: bytes, data: bytes) -> str:
    return hmac.new(secret, data, hashlib.sha256).hexdigest()


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


def compiled(
    name: str,
    key: str | None,
    lower: Callable[[], jax.stages.Lowered],
    platform: str | None = None,
):
    """The program `lower()` gives, compiled (`jax.stages.Compiled`) for
    `platform` (default: JAX's default backend; the key names any other),
    kept in `program_folder()` and read back by later processes of the same
    user.

    Its file, `NAME-DIGEST.jaxprogram`, is keyed by `key` (what the program
    depends on besides code: its static structure, shapes, ...), by
    `code_version()`, by the settings that change what tracing makes
    (float64, matmul precision, Equinox's error mode) and by the machine
    (`_machine`). It holds an HMAC under the user's key (`_secret`), the key
    and the pickled executable; the HMAC is checked before anything else is
    read, so a file that anyone without the key wrote is never unpickled. A
    kept program is loaded instead of calling `lower` and compiling; a file
    that is damaged, forged or holds another key is compiled anew. Without a
    folder, a key (None: not to be kept) or the user's key,
    `lower().compile()`."""
    folder = program_folder()
    secret = None if folder is None or key is None else _secret()
    if secret is None:
        return lower().compile()
    settings = [
        jax.config.jax_enable_x64,
        str(jax.config.jax_default_matmul_precision),
        os.environ.get("EQX_ON_ERROR", ""),
    ]
    head = json.dumps([code_version(), settings, _machine(), key]).encode()
    path = folder / f"{name}-{_mac(secret, head)[:32]}.jaxprogram"
    try:
        mac, content = path.read_bytes().split(b"\n", 1)
        if hmac.compare_digest(mac, _mac(secret, content).encode()):
            kept, payload = content.split(b"\n", 1)
            if kept == head:
                saved = pickle.loads(zlib.decompress(payload))
                return serialize_executable.deserialize_and_load(*saved, platform)
    except Exception:  # missing, damaged or forged: compile again
        pass
    hits = _cache_hits()
    program = lower().compile()
    if _cache_hits() != hits:
        # Loaded from JAX's cache: jaxlib serializes such code without its
        # kernels (it fails when run), so only a program compiled here is kept.
        return program
    partial = None
    try:
        saved = serialize_executable.serialize(program)
        content = head + b"\n" + zlib.compress(pickle.dumps(saved), 1)
        folder.mkdir(parents=True, exist_ok=True)
        # A new file of its own (mode 0600): no name another user could
        # have laid a link at.
        fd, partial = tempfile.mkstemp(dir=folder, prefix=f"{path.name}.")
        with os.fdopen(fd, "wb") as file:
            file.write(_mac(secret, content).encode() + b"\n" + content)
        os.replace(partial, path)  # whole files only, also between processes
        partial = None
    except Exception:  # a read-only folder...: the program is used, not kept
        pass
    finally:
        if partial is not None:
            Path(partial).unlink(missing_ok=True)
    return program
