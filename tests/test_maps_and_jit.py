"""Compilation reuse, behavior maps, save/load and the CLI."""

from concurrent.futures import ThreadPoolExecutor

import diffrax
import jax
import numpy as np
import pytest
import reference as ref

import jaxrock as jr
from jaxrock import _layout, _maps, _model, _programs, _simulate
from jaxrock._chunk import ChunkTask
from jaxrock._scene import MotionLayout, prepare

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
LAM = np.array([1.5, 2.5, 3.5, 5.0, 6.5])
SIZE = np.array([0.3, 1.0, 2.5])


def _compiles() -> int:
    """The chunk loops compiled in this process (one per program and device)."""
    return len(_programs._PROGRAMS)


def test_new_parameters_do_not_recompile():
    run = _simulate._run_jit._cached
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    jr.simulate(jr.Block(3.0, 1.0), base, PULSE)
    before = run._cache_size()
    jr.simulate(
        jr.Block(4.5, 0.7),
        jr.LinearIsolator(1.5, 0.2, 0.8),
        jr.near_fault_pulse("Tabas TAB/SP"),
        duration=20.0,
    )
    jr.simulate(jr.Block(2.0, 3.0), base, jr.MPPulse(0.5, 1.0, 2.0, 45.0, t0=1.0))
    assert run._cache_size() == before


def test_map_equals_simulate_cell_by_cell(linear_map):
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    assert linear_map.outcome.shape == (5, 3)
    for i, lam in enumerate(LAM):
        for j, r in enumerate(SIZE):
            one = jr.simulate(jr.Block(lam, r), base, PULSE)
            assert linear_map.outcome[i, j] == int(one.outcome)
            assert linear_map.impacts[i, j] == int(one.impacts)
            # Maps run the flat loop (one step per iteration), `simulate` one
            # solve per segment: two step sequences at rtol 1e-8 (observed
            # differences up to 2e-8).
            np.testing.assert_allclose(
                linear_map.max_rotation[i, j], float(one.max_rotation), rtol=1e-6
            )
            # A peak of |u| is an event in both: max |u| is an exact extremum
            # (a sampled one is up to 1.2e-3 low on 4 of these cells).
            np.testing.assert_allclose(
                linear_map.max_base_displacement[i, j],
                float(one.max_base_displacement),
                rtol=1e-6,
            )
    # The grid holds every outcome, so the comparison means something.
    assert set(np.unique(linear_map.outcome)) == {0, 1, 2}


def test_the_earliest_of_two_events_in_one_step_wins():
    # Regression: at (2.9, 3.5 m) a peak of |u| lies 14 ms before an apex, in
    # the apex's step. Both engines took the first condition in order (the
    # apex) and lost the peak: max |u| 2.4e-3 low against SciPy. The earliest
    # root now wins (the segment is redone up to just before the apex).
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    a_cm, gamma, phase, freq = jr._ground._TABLE_3_1["San Fernando PCD/SN"]
    acc, t_end, max_step = ref.mp_pulse(a_cm / 100, freq, gamma, phase)
    theirs = ref.simulate(
        2.9, 3.5, ("linear", 2.0, 0.35, 0.5), acc, t_end + 5.0, max_step
    )
    one = jr.simulate(jr.Block(2.9, 3.5), base, PULSE)
    bm = jr.behavior_map([2.9], [3.5], base, PULSE, chunk_size=4, progress=False)
    for u in (float(one.max_base_displacement), bm.max_base_displacement[0, 0]):
        np.testing.assert_allclose(u, theirs["max_base_displacement"], rtol=1e-7)
    assert int(one.impacts) == bm.impacts[0, 0] == theirs["impacts"]
    assert int(one.segments) == bm.segments[0, 0]


def test_automatic_chunks(monkeypatch):
    """By default a map takes as few chunks as keep the cores busy (a multiple
    of their number, of at most MAX_CHUNK_SIZE cells, padded to powers of two
    of at least a lane width), and 610-cell chunks when they are units of
    work for a store or an executor."""
    monkeypatch.setattr(_layout.os, "cpu_count", lambda: 2)
    cpu = jax.devices("cpu")[:1]
    plan = [_layout.chunk_plan(n, "auto", cpu) for n in (15, 2440, 99_856)]
    assert plan == [(15, 64, 1), (1220, 2048, 2), (7133, _layout.MAX_CHUNK_SIZE, 14)]
    assert _layout.chunk_plan(8232, "auto", cpu) == (4116, 8192, 2)  # a suite map
    assert _layout.chunk_size("auto", units=False) == "auto"
    assert _layout.chunk_size("auto", units=True) == _layout.CHUNK_SIZE == 610
    with pytest.raises(ValueError, match="'auto'"):
        _layout.chunk_size("many", units=False)


def test_automatic_chunks_on_a_gpu():
    """On an accelerator a map is one chunk per device, of up to 2**20
    cells, on 131,072 lanes; a small map's chunk is no larger than a power of
    two that holds it (its lanes too: idle lanes would still compute)."""

    class Gpu:
        platform = "gpu"

    gpu = [Gpu()]
    assert _layout.lane_width("gpu") == _layout.ACCELERATOR_LANE_WIDTH == 131072
    assert _layout.lane_width("cpu") == 64
    assert _layout.chunk_plan(2440, "auto", gpu) == (2440, 4096, 1)
    assert _layout.chunk_plan(10**6, "auto", gpu) == (10**6, 1 << 20, 1)
    assert _layout.chunk_plan(3 * 10**6, "auto", gpu) == (10**6, 1 << 20, 3)
    assert _layout.chunk_plan(3 * 10**6, "auto", gpu * 2) == (750_000, 1 << 20, 4)
    assert _layout.chunk_plan(8232, 610, gpu) == (610, 610, 14)


def test_a_small_map_on_a_gpu_machine_runs_on_its_cpu(monkeypatch):
    """Where the local devices are GPUs, a map of at most HOST_MAP_CELLS
    cells runs on the host's CPU and a larger one on the GPUs; without a CPU
    backend (JAX_PLATFORMS=cuda), every map on the GPUs. On a CPU, the CPU."""
    assert _layout.map_devices(10**6) == jax.local_devices()

    class Gpu:
        platform = "gpu"

    gpus, cpus = [Gpu()], jax.local_devices(backend="cpu")

    def local_devices(backend=None):
        return cpus if backend == "cpu" else gpus

    monkeypatch.setattr(_layout.jax, "local_devices", local_devices)
    assert _layout.map_devices(2440) == cpus
    assert _layout.map_devices(_layout.HOST_MAP_CELLS) == cpus
    assert _layout.map_devices(_layout.HOST_MAP_CELLS + 1) == gpus

    def without_cpu(backend=None):
        if backend == "cpu":
            raise RuntimeError("Unknown backend cpu")
        return gpus

    monkeypatch.setattr(_layout.jax, "local_devices", without_cpu)
    assert _layout.map_devices(2440) == gpus


def test_a_map_runs_on_the_devices_given(linear_map):
    """`devices` chooses the devices that run a map's chunks: the same map
    on the CPU given by name; an empty list, anything but devices, or devices
    beside an executor are refused before anything compiles."""
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    bm = jr.behavior_map(LAM, SIZE, base, PULSE, devices=jax.devices("cpu"))
    for field in ("outcome", "status", "impacts"):
        np.testing.assert_array_equal(getattr(bm, field), getattr(linear_map, field))
    np.testing.assert_allclose(bm.max_rotation, linear_map.max_rotation, atol=1e-9)
    with ThreadPoolExecutor(1) as pool:
        for devices, executor in (([], None), (["cpu"], None), (jax.devices(), pool)):
            with pytest.raises(ValueError, match="`devices`"):
                jr.behavior_map(
                    LAM, SIZE, base, PULSE, devices=devices, executor=executor
                )


def test_chunking_does_not_change_results(linear_map):
    whole = jr.behavior_map(
        LAM, SIZE, jr.LinearIsolator(2.0, 0.35, 0.5), PULSE, chunk_size=None
    )
    # Integer results are identical; floats agree to rounding (XLA vectorises a
    # batch of 15 lanes differently from batches of 4; rocking amplifies the
    # last-bit differences to about 1e-11).
    for k in ("outcome", "impacts", "status"):
        np.testing.assert_array_equal(getattr(whole, k), getattr(linear_map, k))
    for k in ("max_rotation", "max_base_displacement", "uplift_time"):
        np.testing.assert_allclose(
            getattr(whole, k), getattr(linear_map, k), rtol=1e-9, atol=1e-15
        )


def test_shared_translation_changes_no_bit(monkeypatch):
    """Maps run each (base, motion, slenderness)'s pure-translation phase once
    (a pilot) and start its cells from there; the same loop with every cell
    run from t = 0 gives the very same numbers, step counts included."""
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    calls, original = [], _maps._compute_chunk

    def counting(task, device=None):
        calls.append(bool(task.pilot))  # pilot pass or not
        return original(task, device)

    monkeypatch.setattr(_maps, "_compute_chunk", counting)
    shared = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=None, progress=False)
    assert calls == [True, False]  # the pilots, then the cells from their carries
    lanes = _layout.CPU_LANE_WIDTH  # a map of 15 cells: one chunk of 64 lanes

    def pad(x):
        x = np.asarray(x)
        return np.concatenate([x, np.repeat(x[-1:], lanes - x.size, axis=0)])

    each = lambda tree: jax.tree_util.tree_map(  # noqa: E731
        lambda x: pad(np.full(LAM.size * SIZE.size, x)), tree
    )
    lam, r = pad(np.repeat(LAM, SIZE.size)), pad(np.tile(SIZE, LAM.size))
    bases, motions = each(base), each(PULSE)
    initial = jax.vmap(lambda b, base, m: _model.initial_carry(b, base, prepare(m)))(
        jr.Block(lam, r), bases, motions
    )
    initial = jax.tree_util.tree_map(np.asarray, initial)
    opts = jr.SolverOptions(1e-8, 1e-10, 16384, 2000, 1e-6)
    duration = jr._misc.as_float(float(PULSE.end_time) + 5.0)
    count, pilot = np.asarray(LAM.size * SIZE.size), np.asarray(False)
    one = _maps._numpy(base)  # the base of every cell
    before = _compiles()
    alone = original(
        ChunkTask(
            lam,
            r,
            bases,
            motions,
            None,
            None,
            initial,
            one,
            duration,
            opts,
            count,
            pilot,
            MotionLayout.PER_CELL,
        )
    )
    assert _compiles() == before  # the map's own loop
    for k in _maps._FIELDS:
        expected = alone[k].reshape(shared.outcome.shape)
        np.testing.assert_array_equal(getattr(shared, k), expected, err_msg=k)


def test_progress_bar_counts_each_chunk_once(linear_map, capsys):
    """A compiled map runs all its chunks at once; the bar still ends at 4/4."""
    again = jr.behavior_map(
        LAM, SIZE, jr.LinearIsolator(2.0, 0.35, 0.5), PULSE, chunk_size=4
    )
    bar = capsys.readouterr().err.replace("\r", "\n").splitlines()
    assert [line for line in bar if "behavior map" in line][-1].count("4/4") == 1
    np.testing.assert_array_equal(again.outcome, linear_map.outcome)
    np.testing.assert_array_equal(again.max_rotation, linear_map.max_rotation)


def test_new_map_parameters_reuse_compile(linear_map):
    before = _compiles()
    jr.behavior_map(
        LAM + 0.05,
        SIZE * 1.1,
        jr.LinearIsolator(1.5, 0.1, 0.3),
        jr.near_fault_pulse("Northridge JFA/SN"),
        chunk_size=4,
    )
    assert _compiles() == before


def test_maps_of_other_sizes_reuse_compile():
    # Chunks are padded to powers of two with cells that are never analysed:
    # 5, 6 and 7 cells share one compile (and the padding is not counted).
    maps = []
    grids = [
        ([2.0, 3.0, 4.0, 5.0, 6.0], [1.0]),
        ([2.5, 3.5], [0.5, 1.0, 2.0]),
        (np.linspace(1.5, 6.5, 7), [0.8]),
    ]
    for k, (lam, size) in enumerate(grids):
        maps.append(jr.behavior_map(lam, size, jr.FixedBase(), PULSE))
        if k == 0:
            after_first = _compiles()
    assert _compiles() == after_first
    for bm in maps:
        assert bm.outcome.shape == (len(bm.slenderness), len(bm.size))
        assert np.all(bm.status == jr.Status.SUCCESS) and np.all(bm.steps > 0)
        assert 0 < bm.lane_efficiency <= 1


def test_fixed_map_no_rocking_cells_obey_threshold():
    bm = jr.behavior_map(
        np.linspace(1.2, 4.0, 8), [0.5, 2.0], jr.FixedBase(), PULSE, chunk_size=8
    )
    ts = np.linspace(0.0, float(PULSE.end_time), 100001)
    pga = float(np.max(np.abs(np.asarray(jax.vmap(PULSE.acceleration)(ts)))))
    lam = bm.slenderness[:, None] * np.ones_like(bm.size)[None, :]
    calm = bm.outcome == jr.Outcome.NO_ROCKING
    assert np.all(1.0 / lam[calm] >= pga / 9.81 * (1 - 1e-6))
    assert np.all(1.0 / lam[~calm] <= pga / 9.81 * (1 + 1e-6))
    assert calm.any() and (~calm).any()


def test_flat_loop_locates_small_apexes_like_simulate():
    # Regression: a Newton loop that bisected away from a converged root put
    # apexes of tiny excursions 1e-6 rad/s off, and max rotation 1.7% off at
    # (2.5, 2.5 m), a cell with 24 impacts of amplitude down to 1e-6 alpha.
    size = np.array([0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0])
    bm = jr.behavior_map([2.5], size, jr.FixedBase(), PULSE, chunk_size=8)
    # These rotations are 0.5-5% of alpha: at rtol 1e-8 / atol 1e-10 both engines
    # sit within 4e-6 of a SciPy solution at rtol 1e-11 (on opposite sides, 5e-6
    # apart at most), far from the bug's 1.7e-2.
    for j, r in enumerate(size):
        one = jr.simulate(jr.Block(2.5, r), jr.FixedBase(), PULSE)
        assert bm.impacts[0, j] == int(one.impacts)
        assert bm.max_rotation[0, j] == pytest.approx(float(one.max_rotation), rel=2e-5)
    assert bm.impacts[0, 4] > 10


def test_ensembles_add_leading_axes(linear_map):
    bases = jr.LinearIsolator(period=np.array([1.5, 2.0]), damping=0.35, mass_ratio=0.5)
    bm = jr.behavior_map(LAM, SIZE, bases, PULSE, chunk_size=4)
    assert bm.outcome.shape == (2, 5, 3)
    np.testing.assert_array_equal(bm.outcome[1], linear_map.outcome)
    np.testing.assert_allclose(bm.max_rotation[1], linear_map.max_rotation, rtol=1e-9)
    assert not np.array_equal(bm.max_base_displacement[0], bm.max_base_displacement[1])
    pulses = jr.MPPulse(np.array([0.3, 1.15]), 0.68, 1.6, 180.0)
    bm = jr.behavior_map(
        LAM, SIZE, jr.LinearIsolator(2.0, 0.35, 0.5), pulses, chunk_size=4
    )
    assert bm.outcome.shape == (2, 5, 3)
    np.testing.assert_array_equal(bm.outcome[1], linear_map.outcome)
    assert np.all(bm.outcome[0] <= bm.outcome[1])  # a weaker pulse does no more harm


def test_a_batch_of_one_isolator_keeps_its_axis(linear_map):
    base = jr.LinearIsolator(np.array([2.0]), 0.35, 0.5)
    bm = jr.behavior_map(LAM, SIZE, base, PULSE, chunk_size=4, progress=False)
    assert bm.outcome.shape == (1,) + linear_map.outcome.shape
    np.testing.assert_array_equal(bm.outcome[0], linear_map.outcome)
    assert "T_s = 2 s" in bm.base


def test_flat_loop_retries_an_event_newton_did_not_locate():
    # Regression: Dopri8 takes long steps. Falling from a tiny apex, an impact
    # lies near the start of such a step, the secant guess is far off, and 8
    # Newton iterations did not converge: the impact was "located" with theta
    # 1e-7 rad off zero, each half-cycle gained energy, and the block rocked on
    # (182 impacts at (4.0, 0.5 m) where `simulate` and SciPy count 69). An
    # event not located to 1e-12 s now retries a shorter step.
    size = np.array([0.5, 1.0])
    solver = diffrax.Dopri8()
    bm = jr.behavior_map([4.0], size, jr.FixedBase(), PULSE, solver=solver)
    for j, r in enumerate(size):
        one = jr.simulate(jr.Block(4.0, r), jr.FixedBase(), PULSE, solver=solver)
        assert bm.impacts[0, j] == int(one.impacts)
        assert bm.max_rotation[0, j] == pytest.approx(float(one.max_rotation), rel=1e-7)
    assert bm.impacts[0, 0] > 60


AFTER_PULSE = float(PULSE.end_time) + 5.0


@pytest.mark.parametrize(
    "duration, max_segments",
    [
        (AFTER_PULSE, 2000),
        (float(PULSE.end_time) + 0.25, 2000),
        (AFTER_PULSE, 15),
        (None, 2000),
    ],
    ids=["window-after-the-pulse", "window-ends-mid-rise", "segment-limit", "decided"],
)
def test_fixed_base_free_rocking_tail_equals_simulate(duration, max_segments):
    """On a fixed base a map finishes the rocking after the pulse in closed form
    (`_free.py`); `simulate` in a window integrates it. Every field they share
    agrees: with a window that ends while blocks rise to their highest apex
    (theta at the window's end, by bisection), and with a segment limit hit
    in the tail. The grid holds blocks past their corner when the pulse ends
    ((2.7, 0.6 m): integrated on, they overturn) and long Zeno tails of small
    impacts. Run until decided, `simulate` finishes the tail in closed form
    too, down to rest."""
    lam, size = [2.7, 4.0, 6.0], [0.6, 1.5]
    bm = jr.behavior_map(
        lam, size, jr.FixedBase(), PULSE, duration=duration, max_segments=max_segments
    )
    for i, j in np.ndindex(bm.outcome.shape):
        one = jr.simulate(
            jr.Block(lam[i], size[j]),
            jr.FixedBase(),
            PULSE,
            duration=duration,
            max_segments=max_segments,
        )
        for k in ("outcome", "impacts", "segments", "status"):
            assert getattr(bm, k)[i, j] == int(getattr(one, k)), (lam[i], size[j], k)
        assert bm.max_rotation[i, j] == pytest.approx(float(one.max_rotation), rel=1e-6)
    if max_segments < 2000:  # some cells stop at the limit, and say so
        assert np.sum(bm.status == jr.Status.MAX_SEGMENTS) >= 2
        assert bm.counts()["not_converged"] == np.sum(
            bm.status == jr.Status.MAX_SEGMENTS
        )
        assert "NOT CONVERGED" in bm.summary()
    elif duration is None or duration == AFTER_PULSE:
        assert bm.outcome[0, 0] == jr.Outcome.OVERTURNED
        assert bm.impacts.max() > 30
    else:  # blocks still rising at the window's end, and at their highest
        full = jr.behavior_map(lam, size, jr.FixedBase(), PULSE)
        rocking = bm.outcome == jr.Outcome.ROCKING
        assert np.sum(rocking & (bm.max_rotation < full.max_rotation * (1 - 1e-6))) >= 2
