"""`BehaviorMap`, the result of a map, and its two file formats (NetCDF
through xarray, and NumPy's .npz)."""

import json
import os
import zipfile

import equinox as eqx
import numpy as np

from ._files import atomic_write
from ._labeled import ATTRS, Coordinates, dataset, read, suffix, write
from ._misc import counted, is_count
from ._results import RESPONSE_FIELDS, Outcome, Status

_FIELDS = RESPONSE_FIELDS


class BehaviorMap(eqx.Module):
    """The results of `behavior_map`: one analysis per block of a grid.

    The grid's cells are the blocks (slenderness lambda = h / b, size r in m)
    of `slenderness` x `size`. Every per-cell field has shape
    (..., n_slenderness, n_size), with leading axes for a batch of bases, then
    of motions; it holds the value of the same field of `Response` for that
    cell. `save` writes a map to a file and `load` reads it back.

    Attributes:
        slenderness: the grid's values of lambda = h / b (-), 1-D.
        size: the grid's values of r, the half-diagonal (m), 1-D.
        outcome: the `Outcome` codes.
        max_rotation: max |theta| / alpha (-), pi / (2 alpha) where the block
            overturns.
        max_base_displacement: max |u| (m); 0 on a fixed base.
        impacts: the numbers of impacts.
        uplift_time: the time of the first uplift (s); NaN where none.
        status: the `Status` codes; anything but SUCCESS marks a cell whose
            numbers are not final.
        steps: the solver's steps of each analysis (on a fixed base, of its
            integrated part: free rocking after the excitation is finished in
            closed form).
        segments: the segments (events) of each analysis.
        base: a description of the base.
        motion: a description of the motion.
        seconds: the wall time of the computation (s), compilation included on
            a first call.
        lane_efficiency: the share (0 to 1) of the executed lane-steps that
            advanced an unfinished analysis (vmapped lanes wait for the
            slowest one).
        motion_names: the records' names of a map under a suite of records
            (its leading motion axis); None otherwise.
        coordinates: the names of the leading axes and the parameters of the
            base and the motion along them (`Coordinates`); None for a map
            read from a file that does not hold them.

    Examples:
        >>> import jaxrock as jr
        >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
        ...                      jr.near_fault_pulse("Northridge JFA/SN"))
        >>> bm.outcome
        array([[0, 0],
               [2, 1]])
        >>> bm.max_rotation.round(3)
        array([[0.   , 0.   ],
               [9.511, 0.036]])
    """

    slenderness: np.ndarray
    size: np.ndarray
    outcome: np.ndarray
    max_rotation: np.ndarray
    max_base_displacement: np.ndarray
    impacts: np.ndarray
    uplift_time: np.ndarray
    status: np.ndarray
    steps: np.ndarray
    segments: np.ndarray
    base: str
    motion: str
    seconds: float
    lane_efficiency: float = float("nan")
    # The records' names of a map under a suite (its leading motion axis).
    motion_names: tuple | None = None
    coordinates: Coordinates | None = None

    def select(self, index: int) -> "BehaviorMap":
        """The map at `index` of its leading axis (a suite's record, an
        ensemble's isolator or pulse), labelled with the record's name; its
        `coordinates` hold that member's parameters, and a map under a suite
        keeps the records' names unless the axis is the suite's."""
        if self.outcome.ndim < 3:
            raise ValueError("the map has no leading batch axis to select from")
        n = self.outcome.shape[0]
        if not is_count(index) or not -n <= index < n:
            raise ValueError(
                f"`index` must be an integer in [{-n}, {n}), got {index!r}"
            )
        index = int(index) % n
        fields = {k: getattr(self, k)[index] for k in _FIELDS}
        names, c = self.motion_names, self._coordinates()
        if self.coordinates is None:  # (read from a file without them) a guess
            on_records = names is not None and len(names) == self.outcome.shape[0]
        else:
            on_records = c.dims[0].startswith("record")
        one = on_records and names is not None and len(names) == self.outcome.shape[0]
        # A record of the suite without a name is labelled as a member.
        one = one and names[index] is not None
        member = f" [{_member_label(c, index) or index}]"
        on_bases = c.dims[0].startswith("base")
        motion = names[index] if one else self.motion + ("" if on_bases else member)
        return BehaviorMap(
            slenderness=self.slenderness,
            size=self.size,
            **fields,
            base=self.base + (member if on_bases else ""),
            motion=motion,
            seconds=self.seconds,
            lane_efficiency=self.lane_efficiency,
            motion_names=None if on_records else names,
            coordinates=c.select(index),
        )

    def _coordinates(self) -> Coordinates:
        return self.coordinates or Coordinates.unlabeled(self.outcome.ndim - 2)

    def counts(self) -> dict[str, int]:
        """The number of cells per outcome, of undecided, sliding and flying
        cells and of cells that did not converge.

        Returns:
            A dict: "no_rocking", "rocking" and "overturned" count the cells of
            each `Outcome`; "undecided" the cells whose fate was still open at
            the end of the window (`Status.UNDECIDED`), "sliding" those whose
            block would slide (`Status.SLIDING`, a map with a `friction`),
            "free_flight" those whose ground fell faster than gravity
            (`Status.FREE_FLIGHT`, a vertical motion), "capacity_exceeded"
            those whose isolator reached its `capacity`
            (`Status.CAPACITY_EXCEEDED`), "not_converged" those
            with any other status but SUCCESS (each counted under its
            outcome as well).

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> bm.counts()
            {'no_rocking': 2, 'rocking': 1, 'overturned': 1, 'undecided': 0, 'sliding': 0, 'free_flight': 0, 'capacity_exceeded': 0, 'not_converged': 0}
        """  # noqa: E501
        out = {o.name.lower(): int(np.sum(self.outcome == o)) for o in Outcome}
        apart = {
            "undecided": Status.UNDECIDED,
            "sliding": Status.SLIDING,
            "free_flight": Status.FREE_FLIGHT,
            "capacity_exceeded": Status.CAPACITY_EXCEEDED,
        }
        for name, status in apart.items():
            out[name] = int(np.sum(self.status == status))
        known = [Status.SUCCESS, *apart.values()]
        out["not_converged"] = int(np.sum(~np.isin(self.status, known)))
        return out

    def summary(self) -> str:
        """One line: the analyses, their wall time (s) and the cells per outcome.

        Cells that did not converge are flagged; the motion and the base close
        the line.

        Returns:
            The line, a str.

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> print(bm.summary())  # doctest: +ELLIPSIS
            4 analyses in ... s: 2 no rocking, 1 rocking, 1 overturned [MP pulse ...]
        """
        c = self.counts()
        text = (
            f"{counted(self.outcome.size, 'analysis', 'analyses')} in "
            f"{self.seconds:.2f} s: "
            f"{c['no_rocking']} no rocking, {c['rocking']} rocking, "
            f"{c['overturned']} overturned"
        )
        if c["undecided"]:
            text += f", {c['undecided']} undecided (fate open at the window's end)"
        if c["sliding"]:
            text += f", {c['sliding']} sliding (friction exceeded)"
        if c["capacity_exceeded"]:
            text += (
                f", {c['capacity_exceeded']} past the isolator's capacity "
                "(it would hit its stop)"
            )
        if c["free_flight"]:
            text += f", {c['free_flight']} in free flight (ground fell faster than g)"
        if c["not_converged"]:
            text += f", {c['not_converged']} NOT CONVERGED (see status)"
        return text + f" [{self.motion}; {self.base}]"

    def to_xarray(self):
        """The map as an `xarray.Dataset` with named dimensions.

        Dimensions: the leading (batch) axes of `coordinates` ("base", then
        "motion" for a batch of pulses or "record" for a suite of records),
        then "slenderness" and "size". Coordinates: the grid (slenderness
        lambda = h / b, -; size r, m) and the parameters of the base and the
        motion along the batch axes, with their SI units in `attrs` (e.g.
        `period` (s) of a batch of `LinearIsolator`, `amplitude` (m/s) of a
        batch of pulses, `record` the records' names), 0-d where one value. A
        1-D coordinate of distinct values is an index: `ds.sel(period=2.0)`.
        Data variables: the per-cell fields, their meanings and units in
        `attrs` (`outcome` and `status` list their codes as `flag_values`
        and `flag_meanings`). Attributes: `base` and `motion` (descriptions),
        `seconds` (s), `lane_efficiency` and, under a suite, `motion_names`.

        Needs xarray (`pip install "jaxrock[xarray]"`).

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> ds = bm.to_xarray()
            >>> ds.outcome.dims, int(ds.outcome.sel(slenderness=6.0, size=0.5))
            (('slenderness', 'size'), 2)
            >>> float(ds.frequency), ds.frequency.attrs["units"]  # the pulse's f_p
            (0.33, 'Hz')
        """
        c = self._coordinates()
        dims = c.dims + ("slenderness", "size")
        coords = {
            k: ((k,), getattr(self, k), ATTRS[k]) for k in ("slenderness", "size")
        }
        return dataset(
            {k: (dims, getattr(self, k)) for k in _FIELDS},
            coords | c.coords,
            self._attributes(),
        )

    def _attributes(self) -> dict:
        """The metadata: base, motion, seconds, lane_efficiency, motion_names
        (when a suite's, None as "")."""
        out = dict(
            base=self.base,
            motion=self.motion,
            seconds=float(self.seconds),
            lane_efficiency=float(self.lane_efficiency),
        )
        if self.motion_names is not None:
            out["motion_names"] = ["" if n is None else n for n in self.motion_names]
        return out

    @classmethod
    def from_xarray(cls, ds) -> "BehaviorMap":
        """The map of a Dataset of `BehaviorMap.to_xarray` (or read from its
        file).

        Raises:
            ValueError: a Dataset without the map's variables or attributes
                (base, motion, seconds), or whose arrays disagree (see
                `load`).

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> jr.BehaviorMap.from_xarray(bm.to_xarray()).counts() == bm.counts()
            True
        """
        names = ("slenderness", "size") + _FIELDS
        missing = [k for k in names if k not in ds.variables]
        missing += [k for k in ("base", "motion", "seconds") if k not in ds.attrs]
        if missing:
            raise ValueError(f"missing {', '.join(missing)}")
        arrays = {k: ds[k].values for k in names}
        _check_map_arrays(arrays)
        dims = ds["outcome"].dims[:-2]
        suite = ds.attrs.get("motion_names")
        return cls(
            **arrays,
            base=str(ds.attrs["base"]),
            motion=str(ds.attrs["motion"]),
            seconds=float(ds.attrs["seconds"]),
            lane_efficiency=float(ds.attrs.get("lane_efficiency", np.nan)),
            motion_names=None
            if suite is None
            else tuple(str(n) or None for n in np.atleast_1d(suite)),
            coordinates=Coordinates.from_dataset(ds, dims, ("slenderness", "size")),
        )

    def save(self, path) -> None:
        """Write the map to a file, in the format its suffix names.

        `.npz`: a compressed NumPy file (every array, and the metadata as
        JSON); `.nc`: NetCDF-4 (by h5netcdf); `.zarr`: a Zarr store (a
        folder, replaced if it exists). NetCDF and Zarr hold the Dataset of
        `to_xarray` and need `pip install "jaxrock[xarray]"`. Every format
        holds the arrays, the batch axes' coordinates and the metadata (base,
        motion, seconds, lane_efficiency, motion_names); `BehaviorMap.load`
        reads them back.

        Args:
            path: the file's path (str or path-like), ending in `.npz`, `.nc`
                or `.zarr` (in any case: `map.NPZ` is a `.npz` file, written
                at that name); a name without a suffix gets `.npz` appended
                (`map` writes `map.npz`, which `load("map")` reads).

        The file is written under a temporary name beside `path` and renamed
        over it once whole (`.zarr`: the folder): a full disk or an
        interruption leaves a file already at `path` as it was, and no
        temporary file.

        Raises:
            ValueError: any other suffix, an empty `path`, a `.npz` or `.nc`
                path that names a folder (an existing one, or one ending in a
                separator), or a `.zarr` path that exists and is not a Zarr
                store.
            OSError: the file cannot be written (a full disk, no permission);
                the message names `path`.

        Examples:
            >>> import os, tempfile, jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> path = os.path.join(tempfile.mkdtemp(), "map.npz")
            >>> bm.save(path)
            >>> jr.BehaviorMap.load(path).counts() == bm.counts()
            True
        """
        kind = suffix(path)
        if kind != ".zarr":
            path = _file(path, kind)
        if kind != ".npz":
            write(self.to_xarray(), path, kind)
            return
        meta = self._attributes() | {
            "motion_names": self.motion_names,
            "coordinates": None
            if self.coordinates is None
            else self.coordinates.to_json(),
        }
        # Strict JSON: NaN as null.
        meta = {k: None if v != v else v for k, v in meta.items()}
        arrays = {k: getattr(self, k) for k in ("slenderness", "size") + _FIELDS}
        metadata = json.dumps(meta, allow_nan=False)
        atomic_write(
            path,
            lambda tmp: np.savez_compressed(tmp, metadata=np.array(metadata), **arrays),
        )

    @classmethod
    def load(cls, path) -> "BehaviorMap":
        """Read a map written by `BehaviorMap.save` (`.npz`, `.nc` or `.zarr`).

        Args:
            path: the file's path (str or path-like), as given to `save`: a
                name without a suffix reads the name with `.npz` appended.

        Returns:
            The `BehaviorMap`, with the arrays, coordinates and metadata saved.

        Raises:
            ValueError: a suffix other than `.npz`, `.nc` and `.zarr`, or a
                file that is not such a map (the message names it): missing,
                unreadable or truncated, without some arrays or metadata, with
                arrays whose shapes disagree, or with outcome or status codes
                out of range.

        Examples:
            >>> import os, tempfile, jaxrock as jr
            >>> path = os.path.join(tempfile.mkdtemp(), "map.npz")
            >>> jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                 jr.near_fault_pulse("Northridge JFA/SN")).save(path)
            >>> bm = jr.BehaviorMap.load(path)
            >>> bm.outcome.shape, bm.base
            ((2, 2), 'fixed base')
        """
        kind = suffix(path)
        try:
            if kind != ".npz":
                return cls.from_xarray(read(path, kind))
            return cls._load_npz(_file(path, kind))
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
            raise ValueError(
                f"{str(path)!r} is not a behavior map written by "
                f"BehaviorMap.save: {err}"
            ) from None

    @classmethod
    def _load_npz(cls, path) -> "BehaviorMap":
        names = ("slenderness", "size") + _FIELDS
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in ("metadata",) + names if k not in data.files]
            if missing:
                raise ValueError(f"missing {', '.join(missing)}")
            meta = json.loads(str(data["metadata"]))
            arrays = {k: data[k] for k in names}
        if not isinstance(meta, dict) or not {"base", "motion", "seconds"} <= set(meta):
            raise ValueError("its metadata lacks base, motion or seconds")
        _check_map_arrays(arrays)
        out = _metadata(meta)
        if isinstance(meta.get("coordinates"), dict):
            c = Coordinates.from_json(meta["coordinates"])
            if len(c.dims) != arrays["outcome"].ndim - 2:
                raise ValueError(f"coordinates name {len(c.dims)} leading axes")
            out["coordinates"] = c
        return cls(**arrays, **out)


def _file(path, kind: str) -> str:
    """The file of a map in format `kind` (".npz" or ".nc") at `path`: `path`
    itself, with ".npz" appended to a `.npz` name without a suffix; a
    `ValueError` naming `path` if it is empty or names a folder (or its
    ".npz" name does)."""
    name = os.fsdecode(path)
    if not name:
        raise ValueError(
            "`path` is empty: give a file name ending in .npz, .nc or .zarr"
        )
    file = name
    if kind == ".npz" and not name.lower().endswith(".npz"):
        file = f"{name}.npz"
    if name.endswith(("/", os.sep)) or os.path.isdir(name) or os.path.isdir(file):
        raise ValueError(f"`path` {name!r} is a folder, not a file")
    return file


def _metadata(meta: dict) -> dict:
    """The fields of a map file's metadata: base and motion (strings),
    seconds and lane_efficiency (numbers; null: NaN), motion_names (a list
    of strings or nulls); `ValueError` naming a field of another type."""
    out = {}
    for k in ("base", "motion"):
        if not isinstance(meta[k], str):
            raise ValueError(f"its metadata's {k} is not a string: {meta[k]!r}")
        out[k] = meta[k]
    for k in ("seconds", "lane_efficiency"):
        v = meta.get(k, float("nan"))
        v = float("nan") if v is None else v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"its metadata's {k} is not a number: {v!r}")
        out[k] = float(v)
    names = meta.get("motion_names")
    if names is not None:
        named = isinstance(names, list) and all(
            n is None or isinstance(n, str) for n in names
        )
        if not named:
            raise ValueError(
                f"its metadata's motion_names is not a list of strings: {names!r}"
            )
        out["motion_names"] = tuple(names)
    return out


def _check_map_arrays(arrays: dict) -> None:
    """`ValueError` unless a map's arrays agree: 1-D axes, every field of shape
    (..., n_slenderness, n_size), known outcome and status codes."""
    lam, r = arrays["slenderness"], arrays["size"]
    if lam.ndim != 1 or r.ndim != 1:
        raise ValueError("slenderness and size must be 1-D")
    shape = arrays["outcome"].shape
    if shape[-2:] != (lam.size, r.size):
        raise ValueError(f"outcome has shape {shape}, not (..., {lam.size}, {r.size})")
    for k in _FIELDS:
        if arrays[k].shape != shape:
            raise ValueError(f"{k} has shape {arrays[k].shape}, outcome {shape}")
    _check_codes(arrays)


def _check_codes(arrays: dict) -> None:
    """`ValueError` unless outcome and status hold known codes."""
    for k, codes in (("outcome", Outcome), ("status", Status)):
        if not np.isin(arrays[k], [int(c) for c in codes]).all():
            raise ValueError(f"{k} holds codes other than {[int(c) for c in codes]}")


def check_chunk(arrays: dict, cells=None) -> None:
    """`ValueError` unless a stored chunk's arrays agree: a 1-D index of
    cells (`cells`, if given), a value of each field per cell, floats or
    integers as computed, known codes, and its lane-step counts."""
    index = arrays["index"]
    if index.ndim != 1 or index.dtype.kind not in "iu":
        raise ValueError(f"its index is not cells: {index.dtype} {index.shape}")
    if cells is not None and not np.array_equal(index, cells):
        raise ValueError("its cells are not those the store's order deals it")
    floats = ("max_rotation", "max_base_displacement", "uplift_time")
    for k in _FIELDS:
        x = arrays[k]
        if x.shape != index.shape or x.dtype.kind not in ("f" if k in floats else "iu"):
            raise ValueError(f"{k} is {x.dtype} {x.shape}, for {index.size} cells")
    _check_codes(arrays)
    check_counts(arrays)


def check_counts(arrays: dict) -> None:
    """`ValueError` unless the lane-step counts "useful" and "executed" are
    integers, 0 <= useful <= executed."""
    useful, executed = arrays["useful"], arrays["executed"]
    numbers = all(x.shape == () and x.dtype.kind in "iu" for x in (useful, executed))
    if not (numbers and 0 <= useful <= executed):
        raise ValueError(f"lane-step counts useful {useful}, executed {executed}")


def _member_label(c: Coordinates, index: int) -> str:
    """The parameters that vary along the leading axis of `c`, at `index`
    ("amplitude = 2 m/s"); "" if none is labelled."""
    parts = []
    for name, (dims, values, attrs) in c.coords.items():
        if len(dims) == 1 and dims[0] == c.dims[0] and name != "record":
            units = attrs.get("units", "")
            value = f"{np.asarray(values)[index]:g} {'' if units == '1' else units}"
            parts.append(f"{name} = {value.strip()}")
    return ", ".join(parts)
