"""A map's chunk store: a folder of finished chunks, so that an interrupted map
resumes where it stopped."""

import hashlib
import os
import zipfile
from pathlib import Path

import numpy as np


class ChunkStore:
    """The folder `store=DIR` of `behavior_map`.

    `manifest.json` holds the map's key (its grid, base, motion and options);
    every chunk file carries the key's digest as well, so that a chunk of
    another map is refused even if the manifest is lost. `order.npz` keeps the
    order in which the first run dealt the cells to the chunks. Files are
    written under a temporary name and renamed (atomic): an interruption
    leaves no half file. A chunk that cannot be read (truncated, corrupt)
    counts as missing and is computed again.
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

    def path(self, k: int | str) -> Path:
        """Chunk k's file, or the file named k."""
        return self.folder / (
            f"{k}.npz" if isinstance(k, str) else f"chunk_{k:06d}.npz"
        )

    def read(self, k: int | str, arrays: tuple[str, ...] | None = None) -> dict | None:
        """Chunk k's arrays (or `arrays` of the file named k); None if it is
        missing or unreadable. `ValueError` if it belongs to another map."""
        path = self.path(k)
        if not path.exists():
            return None
        try:
            with np.load(path, allow_pickle=False) as f:
                digest = str(f["key"]) if "key" in f.files else None
                out = {name: f[name] for name in arrays or self.arrays}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None
        if digest != self.digest:
            raise self._foreign(path.name)
        return out

    def write(self, k: int | str, arrays: dict) -> None:
        self._write(
            self.path(k), lambda tmp: np.savez(tmp, key=np.array(self.digest), **arrays)
        )

    def chunks(self, n: int) -> dict[int, dict]:
        """{k: arrays} of the chunks k < n stored and readable."""
        out = {k: self.read(k) for k in range(n)}
        return {k: c for k, c in out.items() if c is not None}

    def dealt(self, order: np.ndarray) -> np.ndarray:
        """The order of the cells that the chunks are dealt from: the stored
        one, else `order`, which is stored."""
        stored = self.read("order", ("order",))
        if stored is not None:
            return stored["order"]
        self.write("order", {"order": order})
        return order
