"""Results as labeled arrays (xarray): the coordinates of their batch axes (the
parameters of the base and the motion), and NetCDF and Zarr files."""

import dataclasses
import importlib
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ._files import atomic_write
from ._misc import broadcast_batch_shape
from ._record import Record
from ._results import Outcome, Status

SUFFIXES = (".npz", ".nc", ".zarr")


def require(module: str):
    """Import `module` (xarray, h5netcdf, zarr), or `ImportError` naming the
    extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ImportError(
            f"labeled arrays and NetCDF / Zarr files need {module}: "
            'pip install "jaxrock[xarray]"'
        ) from err


def _flags(name: str, codes) -> dict:
    """The attributes of a variable of codes (CF flags): each code's meaning."""
    return {
        "long_name": name,
        "flag_values": np.array([int(c) for c in codes]),
        "flag_meanings": " ".join(c.name.lower() for c in codes),
    }


# The attributes of the variables a result holds: meaning and SI unit ("1":
# dimensionless).
ATTRS = {
    "slenderness": {"long_name": "slenderness lambda = h / b", "units": "1"},
    "size": {"long_name": "half-diagonal r", "units": "m"},
    "outcome": _flags("outcome", Outcome),
    "status": _flags("status (anything but success: numbers not final)", Status),
    "max_rotation": {
        "long_name": "max |theta| / alpha (pi / (2 alpha) where overturned)",
        "units": "1",
    },
    "max_base_displacement": {"long_name": "max |u| of the base", "units": "m"},
    "impacts": {"long_name": "impacts", "units": "1"},
    "uplift_time": {"long_name": "time of the first uplift (NaN: none)", "units": "s"},
    "steps": {"long_name": "solver steps (of the integrated part)", "units": "1"},
    "segments": {"long_name": "segments (events)", "units": "1"},
}


def _axis_names(kind: str, n: int) -> tuple[str, ...]:
    """The dimensions of a batch of n axes: kind, or kind_0, kind_1, ..."""
    return (kind,) if n == 1 else tuple(f"{kind}_{i}" for i in range(n))


def _values(x) -> np.ndarray:
    """A coordinate's values: numbers as they are, labels as Python str."""
    x = np.asarray(x)
    return x if x.dtype.kind in "biuf" else x.astype(object)


class Coordinates(NamedTuple):
    """The labels of a result's leading (batch) axes.

    Attributes:
        dims: the names of the leading axes: "base" for a batch of bases, then
            "motion" for a batch of pulses or "record" for a suite of records
            ("base_0", "base_1", ... for a batch of several axes).
        coords: name -> (dims, values, attrs), as xarray takes a coordinate:
            each parameter of the base and of the motion over the batch axes
            along which it is given (0-d for one value), its unit in attrs;
            "record" the records' names. A name of both the base and the
            motion (the `gamma` of a friction pendulum and of a pulse) is
            prefixed "base_" and "motion_".

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> bases = jr.LinearIsolator(np.array([1.5, 2.0]), 0.35, 0.5)
        >>> bm = jr.behavior_map([3.0], [1.0], bases,
        ...                      jr.near_fault_pulse("Northridge JFA/SN"))
        >>> dims, period, attrs = bm.coordinates.coords["period"]
        >>> bm.coordinates.dims, dims, period, attrs
        (('base',), ('base',), array([1.5, 2. ]), {'units': 's'})
    """

    dims: tuple[str, ...]
    coords: dict[str, tuple]

    @classmethod
    def unlabeled(cls, n: int) -> "Coordinates":
        """n leading axes without labels ("batch", or "batch_0", ...)."""
        return cls(_axis_names("batch", n), {})

    def select(self, index: int) -> "Coordinates":
        """The labels at `index` of the first leading axis (which goes)."""
        coords = {}
        for name, (dims, values, attrs) in self.coords.items():
            if dims and dims[0] == self.dims[0]:
                dims, values = dims[1:], np.asarray(values[index], values.dtype)
            coords[name] = (dims, values, attrs)
        return Coordinates(self.dims[1:], coords)

    def sizes(self) -> tuple[int, ...]:
        """The lengths of the leading axes, read from the coordinates along
        them (every axis of a base's or motion's batch has one)."""
        found = {}
        for dims, values, _ in self.coords.values():
            found |= dict(zip(dims, np.shape(values)))
        return tuple(found[d] for d in self.dims)

    def to_json(self) -> dict:
        coords = {
            name: {"dims": list(d), "values": np.asarray(v).tolist(), "attrs": a}
            for name, (d, v, a) in self.coords.items()
        }
        return {"dims": list(self.dims), "coords": coords}

    @classmethod
    def from_json(cls, data: dict) -> "Coordinates":
        coords = {
            name: (tuple(c["dims"]), _values(c["values"]), dict(c["attrs"]))
            for name, c in data["coords"].items()
        }
        return cls(tuple(data["dims"]), coords)

    @classmethod
    def from_dataset(cls, ds, dims, skip=()) -> "Coordinates | None":
        """The labels of `dims` in an xarray Dataset (its coordinates but
        `skip`); None for unlabeled axes."""
        coords = {
            name: (c.dims, _values(c.values), dict(c.attrs))
            for name, c in ds.coords.items()
            if name not in skip
        }
        if not coords and tuple(dims) == cls.unlabeled(len(dims)).dims:
            return None
        return cls(tuple(dims), coords)


def _parameters(module, shape, dims) -> dict[str, tuple]:
    """The coordinates of a module's parameters (the fields with a unit) over a
    batch of `shape` with dimensions `dims`: each over the axes it has (a
    parameter broadcast along an axis is not a coordinate of it)."""
    out = {}
    for field in dataclasses.fields(module):
        unit = field.metadata.get("unit")
        x = np.asarray(getattr(module, field.name))
        if unit is None or x.ndim > len(shape):  # (a record's samples)
            continue
        out[field.name] = _coordinate(x, shape, dims, unit)
    return out


def _coordinate(x, shape, dims, unit: str) -> tuple:
    """The coordinate of values `x` over a batch of `shape` with dimensions
    `dims`: over the axes it has (not those it is broadcast along)."""
    x = np.asarray(x)
    lead = len(shape) - x.ndim
    keep = [k for k in range(x.ndim) if x.shape[k] == shape[lead + k]]
    x = x[tuple(slice(None) if k in keep else 0 for k in range(x.ndim))]
    return (tuple(dims[lead + k] for k in keep), x, {"units": unit})


def _base_parameters(base, shape, dims) -> dict[str, tuple]:
    """`_parameters` of a base, with its `capacity` (m) and its `Stop`'s
    (`stop_period`, `stop_damping`) where it has them: a batch of
    capacities or stops is labelled as one of periods is."""
    out = _parameters(base, shape, dims)
    if getattr(base, "capacity", None) is not None:
        out["capacity"] = _coordinate(base.capacity, shape, dims, "m")
    if getattr(base, "stop", None) is not None:
        stop = _parameters(base.stop, shape, dims)
        out |= {"stop_" + name: c for name, c in stop.items()}
    return out


# Names the results give themselves: their dimensions, per-cell fields, the
# restitution axis, and the coordinates and fields of fragility curves and
# spectra. A parameter of one's own isolator or motion named so is prefixed
# "base_" or "motion_", as a name both use is.
_OWN_NAMES = frozenset(ATTRS) | {
    "restitution",
    "restitution_factor",
    "scale",
    "level",
    "damage_state",
    "im",
    "rocked",
    "overturned",
    "exceeded",
    "minimum",
    "frequency_ratio",
    "amplitude_ratio",
}


def _prefixed(part: dict, prefix: str) -> dict:
    """`part` with each name the results use themselves (`_OWN_NAMES`, a
    dimension's name) prefixed."""

    def own(name: str) -> bool:
        dimension = re.fullmatch(r"(base|motion|record|batch)(_\d+)?", name)
        return name in _OWN_NAMES or dimension is not None

    return {(prefix + n if own(n) else n): c for n, c in part.items()}


def coordinates(base, motion=None, restitution=None) -> Coordinates:
    """The labels of a result's batch axes: base batch, then motion batch,
    then the blocks' own coefficients of restitution (`restitution`: None, or
    the `Block` keyword and its values, an axis if 1-D)."""
    shape = broadcast_batch_shape(base)
    dims = _axis_names("base", len(shape))
    parts = [_prefixed(_base_parameters(base, shape, dims), "base_")]
    if motion is not None:
        shape = motion.batch_shape
        kind = "record" if isinstance(motion, Record) else "motion"
        motion_dims = _axis_names(kind, len(shape))
        found = _prefixed(_parameters(motion, shape, motion_dims), "motion_")
        names = motion.names()
        if names is not None:
            labels = np.array(["" if n is None else str(n) for n in names], object)
            found["record"] = (
                motion_dims,
                labels.reshape(shape),
                {"long_name": "name"},
            )
        parts.append(found)
        dims += motion_dims
        for name in parts[0].keys() & found.keys():
            parts[0]["base_" + name] = parts[0].pop(name)
            found["motion_" + name] = found.pop(name)
    if restitution is not None and np.ndim(restitution[1]) == 1:
        name, values = restitution
        dims += (name,)
        parts.append({name: ((name,), np.asarray(values), {"units": "1"})})
    return Coordinates(dims, {k: v for part in parts for k, v in part.items()})


def dataset(data_vars: dict, coords: dict, attrs: dict):
    """An xarray Dataset: `data_vars` name -> (dims, values), with the
    attributes of `ATTRS` or given as a third item; `coords` name -> (dims,
    values, attrs). A 1-D coordinate of unique values along a batch axis is
    an index (`ds.sel(period=2.0)` selects on it)."""
    xr = require("xarray")
    data_vars = {
        k: v if len(v) == 3 else (*v, ATTRS.get(k, {})) for k, v in data_vars.items()
    }
    ds = xr.Dataset(data_vars, coords=coords, attrs=attrs)
    for name, (dims, values, _) in coords.items():
        if len(dims) == 1 and name != dims[0] and len(set(values)) == len(values):
            ds = ds.set_xindex(name)
    return ds


def suffix(path) -> str:
    """The format of a result's file: ".npz" (also without a suffix: NumPy
    appends it), ".nc" or ".zarr"; `ValueError` for any other."""
    found = Path(path).suffix.lower()
    if found in ("", ".npz"):
        return ".npz"
    if found not in SUFFIXES:
        raise ValueError(
            f"`path` must end in {', '.join(SUFFIXES)} (NumPy, NetCDF, Zarr), "
            f"got {str(path)!r}"
        )
    return found


def write(ds, path, kind: str) -> None:
    """Write `ds` to a NetCDF-4 file (".nc", by h5netcdf) or a Zarr store
    (".zarr", replaced if it exists), whole or not at all (`atomic_write`:
    `OSError` naming `path`)."""
    if kind == ".nc":
        require("h5netcdf")
        atomic_write(path, lambda tmp: ds.to_netcdf(tmp, engine="h5netcdf"))
        return
    require("zarr")
    path = Path(path)
    store = path.is_dir() and (not any(path.iterdir()) or (path / "zarr.json").exists())
    if path.exists() and not store:
        raise ValueError(f"`path` {str(path)!r} exists and is not a Zarr store")
    atomic_write(path, lambda tmp: ds.to_zarr(tmp, mode="w", consolidated=False))


def read(path, kind: str):
    """The Dataset of a file written by `write`, loaded into memory."""
    xr = require("xarray")
    if kind == ".nc":
        require("h5netcdf")
        return xr.load_dataset(path, engine="h5netcdf")
    require("zarr")
    return xr.open_dataset(path, engine="zarr", consolidated=False, chunks=None).load()
