"""Files written whole or not at all.

Every file jaxrock writes (a map, a figure of the command line, a chunk of a
store) is written to a temporary name beside its path and renamed over it
once complete: a full disk or an interruption leaves the earlier file, if any,
and no half-written one.
"""

import hashlib
import os
import re
import shutil
import socket
import threading
from pathlib import Path

# This machine, in the names of temporary files (a folder may be shared by
# several machines): 8 hexadecimal digits of its host name's digest.
_HOST = hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
_OWNER = re.compile(rf"\.{_HOST}-(\d+)-\d+\.tmp(\.[^.]*)?$")


def temporary(path: Path, tag: str = "tmp") -> Path:
    """A name beside `path` for this machine, process and thread, ending in
    the suffix of `path`'s name in lower case (".npz" of "m.NPZ" and of
    ".npz" alike): NumPy and matplotlib read the format from it, and NumPy
    appends ".npz" to a name that does not end in it."""
    owner = f"{_HOST}-{os.getpid()}-{threading.get_ident()}"
    _, dot, ext = path.name.rpartition(".")
    suffix = f".{ext.lower()}" if dot else ""
    return path.with_name(f"{path.name}.{owner}.{tag}{suffix}")


def remove_orphans(folder: Path) -> None:
    """Remove the temporary files in `folder` (`temporary`) that a process
    of this machine left when it was killed mid-write: those whose process
    is gone. Another machine's, or a live process's, are left alone."""
    for path in folder.glob("*.tmp*"):
        match = _OWNER.search(path.name)
        if match is not None and not _alive(int(match.group(1))):
            _remove(path)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process (PermissionError), or unknown
        return True
    return True


def atomic_write(path, write) -> None:
    """`write(tmp)` writes a file, or a folder (a Zarr store), at the path
    `tmp` beside `path`, which it then replaces.

    The file is flushed to the disk before the rename, so that a write the
    system defers fails here, not later. A link at `path` keeps pointing to
    the file it names, which is replaced.

    Raises:
        OSError: writing or renaming failed (a full disk, no permission),
            naming `path`; the temporary file is removed and a file already at
            `path` is left as it was. Anything else `write` raises, after the
            temporary file is removed.
    """
    target = Path(os.path.realpath(path))
    tmp = temporary(target)
    try:
        write(tmp)
        if tmp.is_file():
            _sync(tmp)
        _replace(tmp, target)
    except BaseException as err:
        _remove(tmp)
        if isinstance(err, OSError):
            reason = err.strerror or str(err)
            if err.errno is None:
                raise OSError(f"cannot write {path}: {reason}") from err
            raise OSError(err.errno, f"cannot write {path}: {reason}") from err
        raise


def _sync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _replace(tmp: Path, target: Path) -> None:
    """Rename `tmp` to `target`; a folder over a folder (which rename cannot
    replace when it holds files) moves the old one aside first, and back if
    the rename fails."""
    if not (tmp.is_dir() and target.is_dir()):
        os.replace(tmp, target)
        return
    old = temporary(target, "old")
    os.replace(target, old)
    try:
        os.replace(tmp, target)
    except BaseException:
        os.replace(old, target)
        raise
    shutil.rmtree(old, ignore_errors=True)


def _remove(path: Path) -> None:
    """Remove what a failed write left at `path`, if anything."""
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
    except OSError:
        pass  # the write's own error is the one to report
