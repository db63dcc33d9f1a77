"""A map's chunk store: a folder of finished chunks, so that an interrupted map
resumes where it stopped."""

import hashlib
import os
import time
import zipfile
from pathlib import Path

import numpy as np

# s without a new chunk from the other processes before `wait_for` gives up.
PEER_TIMEOUT = 3600.0


class ChunkStore:
    """The folder `store=DIR` of `behavior_map`.

    `manifest.json` holds the map's key (its grid, base, motion and options);
    every chunk file carries the key's digest as well, so that a chunk of
    another map is refused even if the manifest is lost. Files are written
    under a temporary name and renamed (atomic): no process reads half a file.
    A chunk that cannot be read (truncated, corrupt) counts as missing and is
    computed again.
    """

    def __init__(self, folder, key: str, arrays: tuple[str, ...]):
        if not str(folder).strip():
            raise ValueError("`store` must name a folder, got an empty string")
        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise ValueError(f"`store` {str(self.folder)!r} is a file, not a folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.arrays = arrays
        self.digest = hashlib.sha256(key.encode()).hexdigest()
        manifest = self.folder / "manifest.json"
        if manifest.exists() and manifest.read_text() != key:
            raise self._foreign()
        self._write(manifest, lambda tmp: tmp.write_text(key))

    def _foreign(self, name: str = "") -> ValueError:
        return ValueError(
            f"`store` {str(self.folder)!r} holds chunks of another map"
            + (f" ({name})" if name else "")
            + "; use a new folder"
        )

    @staticmethod
    def _write(path: Path, write) -> None:
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp{path.suffix}")
        write(tmp)
        tmp.replace(path)

    def path(self, k: int) -> Path:
        return self.folder / f"chunk_{k:06d}.npz"

    def has(self, k: int) -> bool:
        """Chunk k is stored and readable."""
        return self.read(k) is not None

    def read(self, k: int) -> dict | None:
        """Chunk k's arrays; None if it is missing or unreadable. `ValueError`
        if it belongs to another map."""
        path = self.path(k)
        if not path.exists():
            return None
        try:
            with np.load(path, allow_pickle=False) as f:
                digest = str(f["key"]) if "key" in f.files else None
                out = {name: f[name] for name in self.arrays}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None
        if digest != self.digest:
            raise self._foreign(path.name)
        return out

    def write(self, k: int, arrays: dict) -> None:
        self._write(
            self.path(k), lambda tmp: np.savez(tmp, key=np.array(self.digest), **arrays)
        )

    def wait_for(self, k: int) -> None:
        """Wait for another process to write chunk k (while the store grows)."""
        path = self.path(k)
        last, count = time.monotonic(), -1
        while not path.exists():
            n = len(list(self.folder.glob("chunk_*.npz")))
            if n != count:
                last, count = time.monotonic(), n
            elif time.monotonic() - last > PEER_TIMEOUT:
                raise RuntimeError(
                    f"no new chunk in {self.folder} for {PEER_TIMEOUT:.0f} s while "
                    f"waiting for {path.name}: has another process stopped?"
                )
            time.sleep(0.05)
