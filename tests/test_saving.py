"""Files written whole or not at all: a map in each format and a figure of the
command line on a full disk (the writer fails midway) keep the file already
there, leave no temporary file and name the path; `--store` naming a file."""

import errno
import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import plot
from jaxrock.cli import main


def _full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _half_then_full(path):
    """A writer that leaves half a file at `path` (or a folder with half a
    file), then finds the disk full."""
    path = Path(path)
    if path.suffix == ".zarr":
        path.mkdir()
        (path / "zarr.json").write_text("{")
    else:
        path.write_bytes(b"PK\x03\x04 half")
    _full_disk()


def _a_map() -> jr.BehaviorMap:
    shape = (2, 1)
    ints = {
        k: np.zeros(shape, dtype=int)
        for k in ("outcome", "impacts", "status", "steps", "segments")
    }
    return jr.BehaviorMap(
        slenderness=np.array([2.0, 3.0]),
        size=np.array([1.0]),
        max_rotation=np.zeros(shape),
        max_base_displacement=np.zeros(shape),
        uplift_time=np.full(shape, np.nan),
        base="fixed base",
        motion="m",
        seconds=1.0,
        **ints,
    )


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name)


@pytest.mark.parametrize("suffix", [".npz", ".nc", ".zarr"])
def test_save_on_a_full_disk_keeps_the_earlier_map(suffix, tmp_path, monkeypatch):
    if suffix != ".npz":
        pytest.importorskip("xarray")
        pytest.importorskip("h5netcdf" if suffix == ".nc" else "zarr")
    import xarray as xr

    path = tmp_path / f"map{suffix}"
    earlier = _a_map()
    earlier.save(path)
    writers = {
        ".npz": (np, "savez_compressed"),
        ".nc": (xr.Dataset, "to_netcdf"),
        ".zarr": (xr.Dataset, "to_zarr"),
    }
    owner, name = writers[suffix]

    def half(*args, **kwargs):
        # np.savez_compressed(file, ...) and Dataset.to_netcdf(self, path, ...)
        _half_then_full(args[0] if owner is np else args[1])

    monkeypatch.setattr(owner, name, half)
    with pytest.raises(OSError, match=rf"cannot write .*map\{suffix}: No space left"):
        _a_map().save(path)
    monkeypatch.undo()
    back = jr.BehaviorMap.load(path)
    assert back.motion == earlier.motion and back.seconds == earlier.seconds
    np.testing.assert_array_equal(back.outcome, earlier.outcome)
    assert _leftovers(tmp_path) == []


def test_save_into_a_new_file_on_a_full_disk_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(np, "savez_compressed", lambda f, **k: _half_then_full(f))
    with pytest.raises(OSError) as caught:
        _a_map().save(tmp_path / "map")  # NumPy's name: map.npz
    assert caught.value.errno == errno.ENOSPC
    assert f"cannot write {tmp_path / 'map.npz'}" in str(caught.value)
    assert list(tmp_path.iterdir()) == []


def test_an_interrupted_write_leaves_the_file(tmp_path):
    from jaxrock._files import atomic_write

    path = tmp_path / "a.txt"
    path.write_text("earlier")

    def interrupted(tmp):
        tmp.write_text("la")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(path, interrupted)
    assert path.read_text() == "earlier" and _leftovers(tmp_path) == []


def test_a_link_keeps_pointing_to_the_file_it_names(tmp_path):
    from jaxrock._files import atomic_write

    (tmp_path / "data").mkdir()
    target = tmp_path / "data" / "a.txt"
    target.write_text("earlier")
    link = tmp_path / "a.txt"
    link.symlink_to(target)
    atomic_write(link, lambda tmp: tmp.write_text("later"))
    assert link.is_symlink() and target.read_text() == "later"


@pytest.fixture
def fake_simulate(monkeypatch):
    """`simulate` without the integration: the command line's own work."""

    class Result:
        def summary(self):
            return "fake response"

    monkeypatch.setattr(jr, "simulate", lambda *args, **kwargs: Result())
    monkeypatch.setattr(plot, "response", lambda r: plt.figure(figsize=(2, 2)))


def test_cli_figure_on_a_full_disk(tmp_path, fake_simulate, monkeypatch, capsys):
    out = tmp_path / "response.png"
    out.write_bytes(b"earlier figure")

    def half(figure, fname, **kwargs):
        _half_then_full(fname)

    monkeypatch.setattr(plt.Figure, "savefig", half)
    assert main(["simulate", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("jaxrock: error: ")
    assert f"cannot write {out}: No space left on device" in err
    assert out.read_bytes() == b"earlier figure"
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("inside", [False, True])
def test_cli_store_naming_a_file(inside, tmp_path, monkeypatch, capsys):
    def computed(*args, **kwargs):
        raise AssertionError("the map ran before --store was checked")

    monkeypatch.setattr(jr, "behavior_map", computed)
    (tmp_path / "notes").write_text("not a folder")
    store = tmp_path / "notes" / ("sub" if inside else "")
    out = str(tmp_path / "map.png")
    assert main(["map", "--store", str(store), "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"--store: {tmp_path / 'notes'} is a file, not a folder" in err


def test_store_inside_a_file_is_named(tmp_path):
    (tmp_path / "notes").write_text("not a folder")
    with pytest.raises(ValueError, match="'.*notes' is a file, not a folder"):
        jr.behavior_map(
            [4.0],
            [1.0],
            jr.FixedBase(),
            jr.near_fault_pulse("San Fernando PCD/SN"),
            store=tmp_path / "notes" / "LinearIsolator",
        )
