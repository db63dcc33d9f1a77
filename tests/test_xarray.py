"""Results as labeled arrays (xarray) and the map's NetCDF, Zarr and NumPy files."""

import sys

import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _maps

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")
pytest.importorskip("zarr")

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


@pytest.fixture(scope="module")
def ensemble():
    """Two isolation periods x two pulse amplitudes on a 2 x 2 grid (the cells'
    shapes of `linear_map`: one compile)."""
    bases = jr.LinearIsolator(period=np.array([1.5, 2.0]), damping=0.35, mass_ratio=0.5)
    amplitudes = np.array([0.3, float(PULSE.amplitude)])
    pulses = jr.MPPulse(amplitudes, PULSE.frequency, PULSE.gamma, PULSE.phase)
    return jr.behavior_map(
        [2.5, 5.0], [0.3, 1.0], bases, pulses, chunk_size=4, progress=False
    )


def assert_same_map(a: jr.BehaviorMap, b: jr.BehaviorMap) -> None:
    """Every field, dtype, label and attribute of two maps agree."""
    for k in ("slenderness", "size") + _maps._FIELDS:
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
        assert getattr(a, k).dtype == getattr(b, k).dtype, k
    for k in ("base", "motion", "seconds", "lane_efficiency", "motion_names"):
        assert getattr(a, k) == getattr(b, k), k
    xr.testing.assert_identical(a.to_xarray(), b.to_xarray())


def test_a_map_is_labeled_by_its_grid_base_and_motion(linear_map, ensemble):
    ds = linear_map.to_xarray()
    assert ds.outcome.dims == ("slenderness", "size")
    for k in _maps._FIELDS:
        np.testing.assert_array_equal(ds[k].values, getattr(linear_map, k))
    assert int(ds.outcome.sel(slenderness=3.5, size=1.0)) == linear_map.outcome[2, 1]
    assert ds.size.attrs["units"] == "m" and ds.uplift_time.attrs["units"] == "s"
    assert ds.outcome.attrs["flag_meanings"] == "no_rocking rocking overturned"
    assert float(ds.period) == 2.0 and ds.period.attrs["units"] == "s"
    assert float(ds.amplitude) == float(PULSE.amplitude)
    assert ds.attrs["base"] == linear_map.base
    assert ds.attrs["seconds"] == linear_map.seconds

    # Batches: one dimension per batch axis, its parameters as coordinates.
    ds = ensemble.to_xarray()
    assert ds.outcome.dims == ("base", "motion", "slenderness", "size")
    np.testing.assert_array_equal(ds.period, [1.5, 2.0])
    np.testing.assert_array_equal(ds.amplitude, [0.3, float(PULSE.amplitude)])
    assert ds.amplitude.attrs["units"] == "m/s" and float(ds.damping) == 0.35
    # The labels select the same analyses as in the single map.
    same = ds.sel(period=2.0, amplitude=float(PULSE.amplitude))
    single = linear_map.to_xarray().sel(slenderness=[2.5, 5.0], size=[0.3, 1.0])
    for k in ("outcome", "impacts", "status"):
        xr.testing.assert_equal(same[k], single[k])
    # `select` is `isel` on the first axis (attributes apart: its motion's name).
    xr.testing.assert_identical(
        ds.isel(base=1), ensemble.select(1).to_xarray().assign_attrs(ds.attrs)
    )


@pytest.mark.parametrize("suffix", [".nc", ".zarr", ".npz", ""])
def test_save_and_load_round_trip_every_format(ensemble, tmp_path, suffix):
    path = tmp_path / f"map{suffix}"
    ensemble.save(path)
    ensemble.save(path)  # over the file or store of the first
    back = jr.BehaviorMap.load(path.with_suffix(suffix or ".npz"))
    assert_same_map(back, ensemble)
    assert back.coordinates.dims == ("base", "motion")


def test_files_and_missing_packages_are_named(linear_map, tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"\.npz, \.nc, \.zarr"):
        linear_map.save(tmp_path / "map.csv")
    with pytest.raises(ValueError, match=r"\.npz, \.nc, \.zarr"):
        jr.BehaviorMap.load(tmp_path / "map.csv")
    (tmp_path / "notes.zarr").write_text("not a store")
    with pytest.raises(ValueError, match="not a Zarr store"):
        linear_map.save(tmp_path / "notes.zarr")
    (tmp_path / "broken.nc").write_bytes(b"CDF\x01 truncated")
    with pytest.raises(ValueError, match="not a behavior map"):
        jr.BehaviorMap.load(tmp_path / "broken.nc")
    linear_map.save(tmp_path / "map.zarr")
    extra = r'pip install "jaxrock\[xarray\]"'
    monkeypatch.setitem(sys.modules, "zarr", None)
    with pytest.raises(ImportError, match=extra):
        jr.BehaviorMap.load(tmp_path / "map.zarr")
    monkeypatch.setitem(sys.modules, "h5netcdf", None)
    with pytest.raises(ImportError, match=extra):
        linear_map.save(tmp_path / "map.nc")
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError, match=extra):
        linear_map.to_xarray()
    linear_map.save(tmp_path / "map.npz")  # NumPy files need none of them
    back = jr.BehaviorMap.load(tmp_path / "map.npz")
    np.testing.assert_array_equal(back.max_rotation, linear_map.max_rotation)
    assert back.coordinates.coords.keys() == linear_map.coordinates.coords.keys()


def test_a_batch_of_capacities_or_stops_labels_its_base_axis(tmp_path):
    """`capacity` (m) and a `Stop`'s period and damping are parameters of the
    base like its period: a batch of them is a coordinate of the base axis
    (it was none: the axis unlabeled), kept through a NetCDF file."""
    capacities = jr.LinearIsolator(2.0, 0.35, 0.5, capacity=np.array([0.05, 0.3]))
    stops = jr.LinearIsolator(
        2.0, 0.35, 0.5, capacity=0.1, stop=jr.Stop(np.array([0.05, 0.1]))
    )
    for base, name, unit in [
        (capacities, "capacity", "m"),
        (stops, "stop_period", "s"),
    ]:
        bm = jr.behavior_map([2.5], [0.4], base, PULSE, progress=False)
        ds = bm.to_xarray()
        assert ds[name].dims == ("base",) and ds[name].attrs["units"] == unit
        assert ds.outcome.sel({name: 0.05}).shape == (1, 1)
        bm.save(tmp_path / f"{name}.nc")
        back = jr.BehaviorMap.load(tmp_path / f"{name}.nc").to_xarray()
        assert back.identical(ds)
