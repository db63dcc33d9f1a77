"""A map's chunk store: a folder of finished chunks, so that an interrupted map
resumes where it stopped."""

import hashlib
import json
import os
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np

from ._files import atomic_write, remove_orphans

_HERE = os.path.dirname(os.path.abspath(__file__)) + os.sep
# What reading a damaged .npz raises (truncated, corrupt, an array missing).
_UNREADABLE = (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile)


class ChunkStore:
    """The folder `store=DIR` of `behavior_map`.

    `manifest.json` holds the map's key (its grid, base, motion and options);
    every chunk file carries the key's digest as well, so that a chunk of
    another map is refused even if the manifest is lost. `order.npz` keeps the
    order in which the first run dealt the cells to the chunks, `pilots.npz`
    the pilots' lane-step counts. Files are written under a temporary name and
    renamed (`_files.atomic_write`): an interruption or a full disk leaves no
    half file, and the temporary file of a process killed mid-write is
    removed when the store is next opened on the same machine. A file that
    cannot be read (truncated, corrupt) or whose arrays disagree counts as
    missing and is computed again, with a warning naming it. A manifest that
    is not a JSON object, or that names another map in a folder of this
    map's files, is damaged and written again (a warning says so); another
    map's chunks are still refused by their digests.
    """

    def __init__(self, folder, key: str, arrays: tuple[str, ...]):
        if not isinstance(folder, (str, os.PathLike)):
            raise ValueError(
                "`store` must be a folder's path (a str or path-like), got "
                f"{type(folder).__name__}"
            )
        if not str(folder).strip():
            raise ValueError("`store` must name a folder, got an empty string")
        self.folder = Path(folder)
        for path in (self.folder, *self.folder.parents):
            if path.exists():
                if not path.is_dir():
                    within = "" if path == self.folder else f": {str(path)!r}"
                    raise ValueError(
                        f"`store` {str(self.folder)!r}{within} is a file, not a folder"
                    )
                break
        self.folder.mkdir(parents=True, exist_ok=True)
        remove_orphans(self.folder)
        self.arrays = arrays
        self.digest = hashlib.sha256(key.encode()).hexdigest()
        manifest = self.folder / "manifest.json"
        if manifest.exists() and manifest.read_bytes() != key.encode():
            damage = self._damage(manifest)
            if damage is None:
                raise self._foreign()
            self.damaged(manifest, damage, "written again")
        atomic_write(manifest, lambda tmp: tmp.write_text(key))

    def _damage(self, manifest: Path) -> str | None:
        """What is wrong with a manifest that is not this map's key, or None if
        it is another map's. The digests that the stored files carry decide
        (this map's: the manifest is damaged; another's: another map), else
        the manifest itself (a JSON object: another map's; else damaged)."""
        digests = set()
        for path in self.folder.glob("*.npz"):
            try:
                with np.load(path, allow_pickle=False) as f:
                    digests.add(str(f["key"]))
            except _UNREADABLE:
                continue
        try:
            text = json.loads(manifest.read_bytes())
            damage = None if isinstance(text, dict) else "not a JSON object"
        except ValueError as err:  # not JSON, not UTF-8
            damage = f"not JSON: {err}"
        if digests and self.digest in digests:
            return damage or "another map's inputs, in a folder of this map's files"
        return None if digests else damage

    def _foreign(self, name: str = "") -> ValueError:
        return ValueError(
            f"`store` {str(self.folder)!r} holds chunks of another map"
            + (f" ({name})" if name else "")
            + "; use a new folder"
        )

    def damaged(self, path: Path, reason, then: str = "computed again") -> None:
        """Warn that the store's file `path` is damaged (`reason`: a text or
        the exception that reading it raised) and is `then`."""
        text = str(reason).strip()
        if not text and isinstance(reason, BaseException):
            text = type(reason).__name__
        # The warning names the first line outside jaxrock (the user's call).
        frame, level = sys._getframe(), 1
        while frame.f_back is not None and frame.f_code.co_filename.startswith(_HERE):
            frame, level = frame.f_back, level + 1
        warnings.warn(
            f"`store` {str(self.folder)!r}: {path.name} is damaged"
            + (f" ({text.splitlines()[0]})" if text else "")
            + f"; {then}",
            RuntimeWarning,
            stacklevel=level,
        )

    def path(self, k: int | str) -> Path:
        """Chunk k's file, or the file named k."""
        return self.folder / (
            f"{k}.npz" if isinstance(k, str) else f"chunk_{k:06d}.npz"
        )

    def read(
        self, k: int | str, arrays: tuple[str, ...] | None = None, check=None
    ) -> dict | None:
        """Chunk k's arrays (or `arrays` of the file named k); None if it is
        missing, unreadable, or `check(arrays)` raises `ValueError` (a
        warning names the damaged file). `ValueError` if it belongs to
        another map."""
        path = self.path(k)
        if not path.exists():
            return None
        out = None
        try:
            with np.load(path, allow_pickle=False) as f:
                digest = str(f["key"]) if "key" in f.files else None
                if digest == self.digest:
                    out = {name: f[name] for name in arrays or self.arrays}
        except _UNREADABLE as err:
            self.damaged(path, err)
            return None
        if digest != self.digest:
            raise self._foreign(path.name)
        if check is not None:
            try:
                check(out)
            except ValueError as err:
                self.damaged(path, err)
                return None
        return out

    def write(self, k: int | str, arrays: dict) -> None:
        """Write chunk k (or the file named k); `OSError` naming the file if
        it cannot be written whole."""
        atomic_write(
            self.path(k), lambda tmp: np.savez(tmp, key=np.array(self.digest), **arrays)
        )

    def chunks(self, n: int, check=None) -> dict[int, dict]:
        """{k: arrays} of the chunks k < n stored, readable and, with
        `check(k, arrays)`, passing it."""
        out = {
            k: self.read(k, check=None if check is None else lambda a, k=k: check(k, a))
            for k in range(n)
        }
        return {k: c for k, c in out.items() if c is not None}

    def order(self, n: int) -> np.ndarray | None:
        """The stored order of the n cells (a permutation), or None."""

        def check(a):
            order = a["order"]
            if order.ndim != 1 or not np.array_equal(np.sort(order), np.arange(n)):
                raise ValueError(f"not an order of the map's {n} cells")

        stored = self.read("order", ("order",), check)
        return None if stored is None else stored["order"]

    def dealt(self, order: np.ndarray) -> np.ndarray:
        """The order of the cells that the chunks are dealt from: the stored
        one, else `order`, which is stored."""
        stored = self.order(order.size)
        if stored is not None:
            return stored
        self.write("order", {"order": order})
        return order
