"""The chunk store of maps (resume, refusal of another map's chunks, damaged
chunks, manifest and pilots' counts, a full disk) and `BehaviorMap.save` /
`load`."""

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _maps
from jaxrock._files import temporary
from jaxrock._store import ChunkStore

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
LAM = np.array([1.5, 2.5, 3.5, 5.0, 6.5])
SIZE = np.array([0.3, 1.0, 2.5])


def test_save_load_roundtrip(linear_map, tmp_path):
    linear_map.save(tmp_path / "m.npz")
    back = jr.BehaviorMap.load(tmp_path / "m.npz")
    for k in ("slenderness", "size", "outcome", "max_rotation", "uplift_time"):
        np.testing.assert_array_equal(getattr(back, k), getattr(linear_map, k))
    assert back.base == linear_map.base and back.motion == linear_map.motion
    assert "rocking" in linear_map.summary()


def test_store_resumes_without_recomputing(tmp_path, monkeypatch, linear_map):
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    first = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    chunks = sorted(tmp_path.glob("chunk_*.npz"))
    assert len(chunks) == 4  # 15 cells in chunks of 4
    chunks[2].unlink()  # as if interrupted before the third chunk was written
    calls = []
    original = _maps._compute_chunk

    def counting(task, device=None):
        calls.append(bool(task.pilot))  # pilot pass or not
        return original(task, device)

    monkeypatch.setattr(_maps, "_compute_chunk", counting)
    again = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    assert calls.count(False) == 1  # the pilots rerun (they are not stored)
    for k in ("outcome", "impacts", "status", "max_rotation", "uplift_time"):
        np.testing.assert_array_equal(getattr(again, k), getattr(first, k))
    np.testing.assert_allclose(first.max_rotation, linear_map.max_rotation, rtol=1e-9)
    # Read back whole, the map counts its pilots' lane-steps as the first run.
    ran = len(calls)
    whole = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    assert len(calls) == ran  # nothing ran
    assert whole.lane_efficiency == again.lane_efficiency == first.lane_efficiency
    with pytest.raises(ValueError, match="another map"):
        jr.behavior_map(
            LAM,
            SIZE,
            jr.LinearIsolator(2.5, 0.35, 0.5),
            PULSE,
            chunk_size=4,
            store=tmp_path,
        )


def test_a_store_of_another_step_limit_is_another_maps(tmp_path):
    """A map run again with the step limit its statuses point to does not
    read the chunks that hit the old one; its motion's default limit, named
    or not, is one map."""
    fixed, lam, size = jr.FixedBase(), LAM[1:4], SIZE[:2]
    short = jr.behavior_map(lam, size, fixed, PULSE, max_steps=3, store=tmp_path)
    assert np.all(short.status == jr.Status.MAX_STEPS)
    with pytest.raises(ValueError, match="another map"):
        jr.behavior_map(lam, size, fixed, PULSE, store=tmp_path)
    full = jr.behavior_map(lam, size, fixed, PULSE, store=tmp_path / "full")
    assert np.all(full.status == jr.Status.SUCCESS)
    again = jr.behavior_map(
        lam, size, fixed, PULSE, max_steps=16384, store=tmp_path / "full"
    )
    np.testing.assert_array_equal(again.max_rotation, full.max_rotation)


def test_store_refuses_another_maps_chunks_without_its_manifest(tmp_path):
    """Each chunk carries its map's key: with the manifest gone, a map of
    another pulse into the same store is refused, not mixed in."""
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    (tmp_path / "manifest.json").unlink()
    other = jr.near_fault_pulse("Northridge JFA/SN")
    with pytest.raises(ValueError, match="another map"):
        jr.behavior_map(LAM, SIZE, base, other, chunk_size=4, store=tmp_path)


def test_store_recomputes_a_truncated_chunk(tmp_path, linear_map):
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    chunk = sorted(tmp_path.glob("chunk_*.npz"))[1]
    chunk.write_bytes(chunk.read_bytes()[:100])
    with pytest.warns(RuntimeWarning, match=rf"{chunk.name} is damaged"):
        again = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    for k in ("outcome", "impacts", "status", "max_rotation"):
        np.testing.assert_array_equal(getattr(again, k), getattr(linear_map, k))
    assert chunk.stat().st_size > 100  # written again, whole


def test_a_store_removes_what_a_killed_write_left(tmp_path):
    """A process killed mid-write leaves its temporary chunk file; opening
    the store on the same machine removes it, but not the temporary file of
    a live process or of another machine (a shared folder)."""
    finished = subprocess.Popen([sys.executable, "-c", "pass"])
    finished.wait()
    chunk = tmp_path / "chunk_000001.npz"
    mine = temporary(chunk)
    orphan = mine.with_name(mine.name.replace(f"-{os.getpid()}-", f"-{finished.pid}-"))
    host = mine.name.split(".")[-3].split("-")[0]
    elsewhere = orphan.with_name(orphan.name.replace(host, "0" * len(host)))
    for path in (mine, orphan, elsewhere):
        path.write_bytes(b"PK")  # a zip's first bytes, cut short
    ChunkStore(tmp_path, "{}", ())
    assert mine.exists() and elsewhere.exists()
    assert not orphan.exists()


def test_store_deals_a_rerun_as_its_first_run(tmp_path, linear_map):
    """The store keeps the order in which its first run dealt the cells to the
    chunks; a rerun, whatever its own pilots' order (other hardware), computes
    the missing chunks of that order, and a stored chunk of another order is
    damaged: computed again."""
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    order = np.load(tmp_path / "order.npz")["order"]
    assert sorted(order) == list(range(15))
    key = (tmp_path / "manifest.json").read_text()
    store = ChunkStore(tmp_path, key, ())
    store.write("order", {"order": order[::-1].copy()})  # as if dealt in reverse
    for chunk in sorted(tmp_path.glob("chunk_*.npz"))[1:]:
        chunk.unlink()
    with pytest.warns(RuntimeWarning, match=r"chunk_000000\.npz is damaged"):
        again = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, store=tmp_path)
    for k in range(4):
        chunk = np.load(tmp_path / f"chunk_{k:06d}.npz")
        np.testing.assert_array_equal(chunk["index"], order[::-1][k::4])
    np.testing.assert_array_equal(again.outcome, linear_map.outcome)
    np.testing.assert_allclose(again.max_rotation, linear_map.max_rotation, rtol=1e-9)


BASE = jr.LinearIsolator(2.0, 0.35, 0.5)


def _stored_map(store, motion=PULSE):
    return jr.behavior_map(LAM, SIZE, BASE, motion, chunk_size=4, store=store)


@pytest.fixture
def computed(monkeypatch):
    """The chunks computed, as a list of "pilots" or "cells"."""
    calls = []
    original = _maps._compute_chunk

    def counting(task, device=None):
        calls.append("pilots" if task.pilot else "cells")
        return original(task, device)

    monkeypatch.setattr(_maps, "_compute_chunk", counting)
    return calls


def _assert_same(again, first):
    for k in ("outcome", "impacts", "status", "max_rotation", "uplift_time"):
        np.testing.assert_array_equal(getattr(again, k), getattr(first, k))
    assert again.lane_efficiency == first.lane_efficiency


def test_store_on_a_full_disk_leaves_no_temporary_file(tmp_path, monkeypatch):
    """A chunk that cannot be written whole leaves no file, and the error names
    it; the rerun computes it."""
    first = _stored_map(tmp_path / "first")
    savez = np.savez

    def full(file, *args, **kwargs):
        if "chunk_000002" not in str(file):
            return savez(file, *args, **kwargs)
        Path(file).write_bytes(b"PK\x03\x04")  # the start of a zip file
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez", full)
    store = tmp_path / "store"
    message = r"cannot write .*chunk_000002\.npz: No space left on device"
    with pytest.raises(OSError, match=message):
        _stored_map(store)
    monkeypatch.undo()
    assert [p.name for p in store.iterdir() if "tmp" in p.name] == []
    assert not (store / "chunk_000002.npz").exists()
    _assert_same(_stored_map(store), first)


def test_store_rebuilds_a_truncated_manifest(tmp_path, computed):
    """Each chunk carries its map's digest: a damaged manifest is written
    again from the map's inputs, and the store resumes as it was."""
    first = _stored_map(tmp_path)
    manifest = tmp_path / "manifest.json"
    key = manifest.read_text()
    manifest.write_text(key[: len(key) // 2])
    computed.clear()
    damaged = r"manifest\.json is damaged.*written again"
    with pytest.warns(RuntimeWarning, match=damaged):
        again = _stored_map(tmp_path)
    assert computed == []  # every chunk and the pilots' counts read back
    assert manifest.read_text() == key
    _assert_same(again, first)
    # Damaged, the manifest of another map's store: its chunks are refused.
    manifest.write_text(key[:10])
    with pytest.raises(ValueError, match="another map"):
        _stored_map(tmp_path, jr.near_fault_pulse("Northridge JFA/SN"))


@pytest.mark.parametrize(
    "damage", ["cells of another chunk", "a field cut short", "outcome", "counts"]
)
def test_store_recomputes_a_chunk_whose_arrays_disagree(damage, tmp_path, computed):
    """A chunk that reads but whose arrays disagree (with each other, with its
    order, with the codes) is damaged: named, and computed again."""
    first = _stored_map(tmp_path)
    path = tmp_path / "chunk_000001.npz"
    with np.load(path) as f:
        arrays = dict(f)
    if damage == "cells of another chunk":
        arrays["index"] = np.load(tmp_path / "chunk_000000.npz")["index"]
    elif damage == "a field cut short":
        arrays["max_rotation"] = arrays["max_rotation"][:-1]
    elif damage == "outcome":
        arrays["outcome"] = arrays["outcome"] + 7
    else:
        arrays["useful"] = arrays["executed"] + 1
    np.savez(path, **arrays)  # with the key of the map
    computed.clear()
    with pytest.warns(RuntimeWarning, match=r"chunk_000001\.npz is damaged"):
        again = _stored_map(tmp_path)
    assert computed.count("cells") == 1
    _assert_same(again, first)


@pytest.mark.parametrize("damage", ["truncated", "counts"])
def test_store_reruns_the_pilots_of_damaged_counts(damage, tmp_path, computed):
    """Read back whole from a store whose pilots' counts are damaged, a map
    runs its pilots again: the same lane_efficiency, and no cell recomputed."""
    first = _stored_map(tmp_path)
    pilots = tmp_path / "pilots.npz"
    if damage == "truncated":
        pilots.write_bytes(pilots.read_bytes()[:60])
    else:
        with np.load(pilots) as f:
            np.savez(pilots, **(dict(f) | {"useful": np.array(-1)}))
    computed.clear()
    with pytest.warns(RuntimeWarning, match=r"pilots\.npz is damaged"):
        again = _stored_map(tmp_path)
    assert set(computed) == {"pilots"}
    _assert_same(again, first)
    computed.clear()
    _assert_same(_stored_map(tmp_path), first)  # counts written again
    assert computed == []


def _saved_map(tmp_path, meta=None, **changes):
    arrays = dict(
        slenderness=np.array([2.0, 3.0]),
        size=np.array([1.0]),
        outcome=np.zeros((2, 1), dtype=int),
        max_rotation=np.zeros((2, 1)),
        max_base_displacement=np.zeros((2, 1)),
        impacts=np.zeros((2, 1), dtype=int),
        uplift_time=np.full((2, 1), np.nan),
        status=np.zeros((2, 1), dtype=int),
        steps=np.zeros((2, 1), dtype=int),
        segments=np.zeros((2, 1), dtype=int),
    )
    arrays.update(changes)
    meta = json.dumps(dict(base="fixed base", motion="m", seconds=0.0) | (meta or {}))
    path = tmp_path / "map.npz"
    np.savez(path, metadata=np.array(meta), **arrays)
    return path


def test_load_reads_a_consistent_map(tmp_path):
    bm = jr.BehaviorMap.load(_saved_map(tmp_path))
    assert bm.outcome.shape == (2, 1) and bm.counts()["no_rocking"] == 2


def test_a_file_without_coordinates_loads_and_converts(tmp_path):
    """A map file without the batch axes' coordinates (as `save` wrote before
    it kept them) reads as before; its leading axes are "batch" ones."""
    pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    names = [f for f in _maps._FIELDS if f not in ("max_rotation", "uplift_time")]
    cube = {k: np.zeros((3, 2, 1), dtype=int) for k in names}
    cube |= dict(max_rotation=np.zeros((3, 2, 1)), uplift_time=np.ones((3, 2, 1)))
    bm = jr.BehaviorMap.load(_saved_map(tmp_path, **cube))
    assert bm.coordinates is None and bm.outcome.shape == (3, 2, 1)
    assert bm.to_xarray().outcome.dims == ("batch", "slenderness", "size")
    assert bm.select(2).to_xarray().outcome.dims == ("slenderness", "size")
    bm.save(tmp_path / "map.nc")
    back = jr.BehaviorMap.load(tmp_path / "map.nc")
    assert back.coordinates is None and back.motion == "m"
    np.testing.assert_array_equal(back.uplift_time, bm.uplift_time)


@pytest.mark.parametrize(
    "changes, message",
    [
        (dict(outcome=np.full((2, 1), 7)), "outcome holds codes"),
        (dict(outcome=np.full((2, 1), -1)), "outcome holds codes"),
        (dict(status=np.full((2, 1), 9)), "status holds codes"),
        (dict(max_rotation=np.zeros((3, 1))), "max_rotation has shape"),
        (dict(outcome=np.zeros((2, 2), dtype=int)), "outcome has shape"),
    ],
)
def test_load_refuses_inconsistent_arrays(tmp_path, changes, message):
    with pytest.raises(ValueError, match=message):
        jr.BehaviorMap.load(_saved_map(tmp_path, **changes))


@pytest.mark.parametrize(
    "meta, message",
    [
        (dict(base=1), "base is not a string"),
        (dict(motion=["m"]), "motion is not a string"),
        (dict(seconds="2"), "seconds is not a number"),
        (dict(lane_efficiency=True), "lane_efficiency is not a number"),
        (dict(motion_names=["a", 3]), "motion_names is not a list of strings"),
    ],
)
def test_load_refuses_metadata_of_other_types(tmp_path, meta, message):
    with pytest.raises(ValueError, match=message):
        jr.BehaviorMap.load(_saved_map(tmp_path, meta))


def test_map_files_hold_strict_json_and_read_back_their_types(tmp_path):
    """NaN is written as null (strict JSON) and read back as NaN; numbers
    read as floats, names as a tuple."""
    meta = dict(seconds=3, lane_efficiency=None, motion_names=["a", None])
    bm = jr.BehaviorMap.load(_saved_map(tmp_path, meta))
    assert isinstance(bm.seconds, float) and np.isnan(bm.lane_efficiency)
    assert bm.motion_names == ("a", None)
    again = tmp_path / "again.npz"
    bm.save(again)
    with np.load(again) as data:
        text = str(data["metadata"])
    json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in {text}"))
    back = jr.BehaviorMap.load(again)
    assert back.seconds == 3.0 and np.isnan(back.lane_efficiency)
    assert back.motion_names == ("a", None)


def test_load_refuses_corrupt_truncated_and_foreign_files(tmp_path):
    good = _saved_map(tmp_path).read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good[: len(good) // 2])
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file at all")
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.arange(3))
    bad_meta = tmp_path / "bad_meta.npz"
    np.savez(bad_meta, metadata=np.array("{not json"), x=np.arange(3))
    for path in (truncated, garbage, foreign, bad_meta, tmp_path / "missing.npz"):
        with pytest.raises(ValueError, match="not a behavior map"):
            jr.BehaviorMap.load(path)


@pytest.fixture
def small_map(tmp_path_factory) -> jr.BehaviorMap:
    """A map read from a file in a folder of its own (`tmp_path` stays empty)."""
    return jr.BehaviorMap.load(_saved_map(tmp_path_factory.mktemp("source")))


@pytest.mark.parametrize("given", ["", "folder", "folder/", "folder.nc"])
def test_save_refuses_an_empty_path_or_a_folder_and_leaves_no_file(
    small_map, tmp_path, monkeypatch, given
):
    """An empty `path` or one naming a folder is a `ValueError` naming `path`,
    raised before anything is written: no map, no temporary file."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder.nc").mkdir()
    with pytest.raises(ValueError, match="`path`.*(empty|is a folder, not a file)"):
        small_map.save(given)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["folder", "folder.nc"]


@pytest.mark.parametrize(
    "given, written",
    [("m.NPZ", "m.NPZ"), ("m.Npz", "m.Npz"), ("m", "m.npz"), (".npz", ".npz")],
)
def test_save_and_load_agree_on_the_file_of_a_path(small_map, tmp_path, given, written):
    """A `.npz` suffix in any case is written at that name, a name without a
    suffix gets `.npz` appended, and `load` reads the map from the path
    given to `save`; no temporary file is left."""
    small_map.save(tmp_path / given)
    assert sorted(p.name for p in tmp_path.iterdir()) == [written]
    back = jr.BehaviorMap.load(tmp_path / given)
    np.testing.assert_array_equal(back.outcome, small_map.outcome)
    assert back.motion == small_map.motion


def test_save_at_an_upper_case_suffix_on_a_full_disk_leaves_nothing(
    small_map, tmp_path, monkeypatch
):
    """NumPy writes the temporary file of `m.NPZ` under a name of its own
    (".npz" appended); a write that fails midway leaves neither that file nor
    a map."""

    def half_then_full(file, **arrays):
        Path(file).write_bytes(b"PK\x03\x04")  # the start of a zip file
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez_compressed", half_then_full)
    with pytest.raises(OSError, match=r"cannot write .*m\.NPZ: No space left"):
        small_map.save(tmp_path / "m.NPZ")
    assert list(tmp_path.iterdir()) == []


def test_a_store_tells_batches_whose_leaves_differ_only_in_shape(tmp_path):
    """Two batches of bases with the same values and descriptions but
    parameters on other axes (period down, damping across, and transposed)
    are two maps: the second is refused, not read from the first's chunks."""
    lam, size = LAM[1:3], SIZE[:2]
    a = jr.LinearIsolator(np.array([[2.0], [2.5]]), np.array([0.1, 0.5]), 0.5)
    b = jr.LinearIsolator(np.array([2.0, 2.5]), np.array([[0.1], [0.5]]), 0.5)
    assert a.describe() == b.describe()
    jr.behavior_map(lam, size, a, PULSE, store=tmp_path, progress=False)
    with pytest.raises(ValueError, match="another map"):
        jr.behavior_map(lam, size, b, PULSE, store=tmp_path, progress=False)


@pytest.mark.parametrize("store", [3, 1.5, ["runs"]])
def test_store_of_another_type_is_refused_by_name(store):
    with pytest.raises(ValueError, match="`store`"):
        jr.behavior_map(
            [3.0],
            [1.0],
            jr.FixedBase(),
            jr.near_fault_pulse("Tabas TAB/SP"),
            store=store,
            progress=False,
        )
