"""Intensity measures against independent integrals on a fine grid, their
scaling, and fragility by any measure."""

import numpy as np
import pytest

import jaxrock as jr

GRAVITY = 9.81


@pytest.fixture(scope="module")
def record():
    rng = np.random.default_rng(3)
    return jr.Record(rng.normal(0.0, 2.0, 40), 0.02)


def _fine(record, per=2000):
    """x_g'' linear between samples, on `per` points an interval."""
    n, dt = int(record.length), float(record.dt)
    t = np.linspace(0.0, (n - 1) * dt, (n - 1) * per + 1)
    return t, np.interp(t, dt * np.arange(n), np.asarray(record.samples))


def _cumulative(t, y):
    return np.concatenate([[0.0], np.cumsum(0.5 * np.diff(t) * (y[1:] + y[:-1]))])


def test_measures_of_a_record_match_integrals_on_a_fine_grid(record):
    t, a = _fine(record)
    v = _cumulative(t, a)
    d = _cumulative(t, v)
    square = _cumulative(t, a * a)
    im = {m: float(jr.intensity_measure(record, m)) for m in jr_measures()}
    assert im["pga"] == np.abs(np.asarray(record.samples)).max()
    # Peaks over the samples; the trapezoids of the fine grid err by
    # O((dt / 2000)^2): 1e-7 of the Arias intensity here.
    assert im["pgv"] == pytest.approx(np.abs(v[::2000]).max(), rel=1e-7)
    assert im["pgv"] == pytest.approx(float(record.pgv), rel=1e-12)
    assert im["pgd"] == pytest.approx(np.abs(d[::2000]).max(), rel=1e-7)
    assert im["arias"] == pytest.approx(np.pi / (2 * GRAVITY) * square[-1], rel=1e-6)
    assert im["cav"] == pytest.approx(_cumulative(t, np.abs(a))[-1], rel=1e-7)
    start, end = np.interp([0.05, 0.95], square / square[-1], t)
    # D5-95 reads the Arias intensity linear between samples: within a sample.
    assert im["d5_95"] == pytest.approx(end - start, abs=float(record.dt))
    spectrum = jr.response_spectrum(record, [0.3])
    assert im["sa:0.3"] == spectrum.pseudo_acceleration[0]


def test_a_record_of_zeros_has_no_significant_duration():
    """D5-95 of a record without energy is NaN, not 0 s; its peaks and
    integrals are 0."""
    zeros = jr.Record(np.zeros(100), 0.01)
    assert np.isnan(float(jr.intensity_measure(zeros, "d5_95")))
    for measure in ("pga", "pgv", "arias", "cav"):
        assert float(jr.intensity_measure(zeros, measure)) == 0.0


def jr_measures():
    return ["pga", "pgv", "pgd", "arias", "cav", "d5_95", "sa:0.3"]


def test_measures_of_a_scaled_suite_scale(record):
    other = jr.Record(np.asarray(record.samples)[::-1][:30], 0.01)
    suite = jr.Record.stack([record, other])
    scaled = suite.scaled([0.5, 3.0])
    power = {"arias": 2, "d5_95": 0}
    for m in jr_measures():
        own = jr.intensity_measure(suite, m)
        np.testing.assert_allclose(
            jr.intensity_measure(scaled, m),
            np.array([0.5, 3.0])[:, None] ** power.get(m, 1) * own,
            rtol=1e-14,
        )
        assert own[1] == pytest.approx(float(jr.intensity_measure(other, m)), rel=1e-14)


def test_block_measures():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    pga = float(jr.intensity_measure(pulse, "pga"))
    pgv = float(jr.intensity_measure(pulse, "pgv"))
    assert pgv == pytest.approx(float(pulse.amplitude), rel=1e-6)  # max v = A
    p = np.sqrt(3 * GRAVITY / (4 * 2.0))
    got = jr.intensity_measure(pulse, "pga_ratio", slenderness=4.0)
    assert float(got) == pytest.approx(pga * 4.0 / GRAVITY, rel=1e-14)
    got = jr.intensity_measure(pulse, "pgv_ratio", slenderness=4.0, size=2.0)
    assert float(got) == pytest.approx(pgv * p * 4.0 / GRAVITY, rel=1e-14)
    got = jr.intensity_measure(pulse, "frequency_ratio", slenderness=4.0, size=2.0)
    assert float(got) == pytest.approx(2 * np.pi * float(pulse.frequency) / p)


def test_fragility_by_spectral_acceleration():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    scales = np.array([0.2, 0.4, 0.6, 0.8, 1.0, 1.2])
    frag = jr.fragility(
        4.0, 1.0, jr.FixedBase(), pulse, scales=scales, measure="sa:1.0"
    )
    sa = float(jr.intensity_measure(pulse, "sa:1.0"))
    np.testing.assert_allclose(frag.im, scales * sa, rtol=1e-14)
    assert frag.measure == "sa:1.0"
    pytest.importorskip("xarray")
    assert frag.to_xarray().im.attrs["long_name"] == "Sa(1 s), 5% damping"


@pytest.mark.parametrize(
    "measure, options, message",
    [
        ("sa:0", {}, "`measure` must be one of pga, "),
        ("sa:x", {}, "or 'sa:T'"),
        ("sa:1_0", {}, "or 'sa:T'"),
        ("sa: 1", {}, "or 'sa:T'"),
        ("sa:inf", {}, "or 'sa:T'"),
        ("pga", {"baseline": "no"}, "`baseline` must be True or False"),
        ("pga_ratio", {"slenderness": True}, "`slenderness` must be finite and > 0"),
        ("PGA", {}, "`measure` must be one of"),
        ("pgv_ratio", {"slenderness": 4.0}, "needs the block's `slenderness` and"),
        ("pga_ratio", {}, "needs the block's `slenderness`"),
        ("pga_ratio", {"slenderness": -1.0}, "`slenderness` must be finite and > 0"),
    ],
)
def test_intensity_measure_names_bad_input(record, measure, options, message):
    with pytest.raises(ValueError, match=message):
        jr.intensity_measure(record, measure, **options)
    if measure.lower() != measure or measure.startswith("sa:"):  # before any map
        with pytest.raises(ValueError, match=message):
            jr.fragility(
                4.0, 1.0, jr.FixedBase(), record, scales=[1.0], measure=measure
            )


def test_frequency_ratio_of_a_record_is_refused(record):
    with pytest.raises(ValueError, match="needs a pulse"):
        jr.intensity_measure(record, "frequency_ratio", slenderness=4.0, size=1.0)


def test_records_scaled_to_a_spectral_acceleration(record):
    other = jr.Record(np.asarray(record.samples)[::-1][:30], 0.01)
    suite = jr.Record.stack([record, other])
    scaled = suite.scaled_to(sa=(0.5, [2.0, 3.0]))
    np.testing.assert_allclose(
        jr.intensity_measure(scaled, "sa:0.5"), [2.0, 3.0], rtol=1e-14
    )
    one = record.scaled_to(sa=(0.5, 2.0))
    assert float(jr.intensity_measure(one, "sa:0.5")) == pytest.approx(2.0, rel=1e-14)


@pytest.mark.parametrize(
    "sa, message",
    [
        ((0.0, 1.0), r"`sa`'s period must be one number in \[0.001, 100.0\]"),
        ((np.nan, 1.0), r"`sa`'s period must be one number in \[0.001, 100.0\]"),
        ((1.0, -2.0), "`sa` must be finite and > 0"),
        ((1.0, np.nan), "`sa` must be finite and > 0"),
        (1.0, r"`sa` must be \(period in s, Sa in m/s\^2\)"),
    ],
)
def test_scaled_to_names_bad_targets(record, sa, message):
    with pytest.raises(ValueError, match=message):
        record.scaled_to(sa=sa)


def test_a_record_with_zero_sa_cannot_be_scaled():
    with pytest.raises(ValueError, match="a record with zero SA cannot be scaled"):
        jr.Record(np.zeros(10), 0.01).scaled_to(sa=(1.0, 2.0))
    with pytest.raises(ValueError, match="give exactly one of"):
        jr.Record(np.ones(10), 0.01).scaled_to(pga=1.0, sa=(1.0, 2.0))


def test_records_scaled_to_a_target_spectrum(record):
    """Each record's log spectrum fitted to the target's in least squares
    (its log residuals average to 0), or one factor fitting the suite's mean
    spectrum; a record's own spectrum times c gives the factor c."""
    other = jr.Record(np.asarray(record.samples)[::-1][:30], 0.01)
    suite = jr.Record.stack([record, other])
    periods = np.geomspace(0.1, 1.0, 12)
    target = 9.81 * jr.asce7_spectrum(periods, sds=1.0, sd1=0.6, tl=8.0)

    def psa(motion):
        return np.asarray(jr.response_spectrum(motion, periods).pseudo_acceleration)

    each = suite.scaled_to_spectrum(periods, target)
    residuals = np.log(target / psa(each)).mean(axis=-1)
    np.testing.assert_allclose(residuals, 0.0, atol=1e-12)
    assert abs(float(each.factor[0]) - float(each.factor[1])) > 1e-3
    one = suite.scaled_to_spectrum(periods, target, each=False)
    assert float(one.factor[0]) == float(one.factor[1])
    mean = psa(one).mean(axis=0)
    assert abs(np.log(target / mean).mean()) < 1e-12
    own = record.scaled_to_spectrum(periods, 2.5 * psa(record))
    assert float(own.factor) == pytest.approx(2.5, rel=1e-13)


@pytest.mark.parametrize(
    "periods, target, message",
    [
        ([0.5, 1.0], [1.0], "`target` must hold one Sa"),
        ([0.5, 1.0], [1.0, -1.0], "`target` must hold one Sa"),
        ([0.0, 1.0], [1.0, 1.0], "`periods`"),
    ],
)
def test_scaled_to_spectrum_names_bad_input(record, periods, target, message):
    with pytest.raises(ValueError, match=message):
        record.scaled_to_spectrum(periods, target)


def test_baseline_correction_removes_a_drift(record):
    """A constant offset a0 and a linear drift a1 t added to a record show in
    its velocity as a0 t + a1 t^2 / 2, which the correction removes: the
    corrected PGV and PGD of the drifting record equal those of the
    original less its own baseline."""
    n, dt = int(record.length), float(record.dt)
    t = dt * np.arange(n)
    drifting = jr.Record(np.asarray(record.samples) + 0.3 + 0.05 * t, dt)
    for measure in ("pgv", "pgd"):
        plain = jr.intensity_measure(drifting, measure)
        corrected = jr.intensity_measure(drifting, measure, baseline=True)
        reference = jr.intensity_measure(record, measure, baseline=True)
        assert corrected == pytest.approx(reference, rel=1e-9)
        assert plain > 1.5 * corrected  # the drift dominates uncorrected
    # Independently: the velocity at the samples (integrated on a fine grid)
    # less its least-squares fit at the samples.
    tf, a = _fine(record, per=200)
    v = _cumulative(tf, a)[::200]
    basis = np.stack([t, t * t], 1)
    coefficients, *_ = np.linalg.lstsq(basis, v, rcond=None)
    expected = np.abs(v - basis @ coefficients).max()
    corrected = float(jr.intensity_measure(record, "pgv", baseline=True))
    assert corrected == pytest.approx(expected, rel=1e-6)
    # A scaled suite's corrected measures scale.
    suite = jr.Record.stack([record, drifting]).scaled(np.array([1.0, 2.0]))
    values = jr.intensity_measure(suite, "pgv", baseline=True)
    assert values[1, 0] == pytest.approx(2 * values[0, 0], rel=1e-12)


def test_pulse_period_of_pulses_and_records():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    assert float(jr.intensity_measure(pulse, "tp")) == pytest.approx(1 / 0.68)
    # A record that is a sampled pulse gives the pulse's period back.
    dt = 0.01
    t = np.arange(0.0, 12.0, dt)
    shifted = jr.MPPulse(1.0, 0.5, 2.0, 90.0, t0=4.0)
    record = jr.Record(np.asarray(shifted.acceleration(t)), dt)
    scaled = jr.Record.stack([record]).scaled(np.array([1.0, 3.0]))
    periods = jr.intensity_measure(scaled, "tp")
    assert periods.shape == (2, 1)
    np.testing.assert_allclose(periods, 2.0, rtol=1e-3)
    shaken = pulse.with_vertical(jr.SinePulse(2.0, 3.0))  # the horizontal's
    assert float(jr.intensity_measure(shaken, "tp")) == pytest.approx(1 / 0.68)
    with pytest.raises(ValueError, match="'tp' needs a pulse"):
        jr.intensity_measure(jr.WithVertical(shaken, pulse), "tp")


def test_peaks_of_a_pulse_that_starts_before_t0_are_those_from_t0():
    """A pulse may start before t = 0 (t0 > -gamma / (2 f_p)); the analyses,
    and the measures read from its samples, start at t = 0: PGA and PGV are
    those of its part from t = 0 too, not of the part no analysis sees."""
    pulse = jr.MPPulse(0.5, 1.0, 2.0, 0.0, t0=-0.5)  # from -1.5 s to 0.5 s
    t = np.linspace(0.0, float(pulse.end_time), 200_001)
    acc = np.abs(np.asarray(pulse.acceleration(t)))
    vel = np.abs(np.asarray(pulse.velocity(t)))
    pga = float(jr.intensity_measure(pulse, "pga"))
    pgv = float(jr.intensity_measure(pulse, "pgv"))
    np.testing.assert_allclose(pga, acc.max(), rtol=1e-6)
    np.testing.assert_allclose(pgv, vel.max(), rtol=1e-6)
    # A pulse that starts at t = 0 keeps its whole closed-form peaks.
    whole = jr.MPPulse(0.5, 1.0, 2.0, 0.0)
    assert float(jr.intensity_measure(whole, "pgv")) == pytest.approx(0.5, rel=1e-9)


@pytest.mark.parametrize("frequency", [0.5, 5.0, 50.0])
def test_a_sine_pulse_s_measures_are_its_closed_forms_at_any_frequency(frequency):
    """x_g'' = a sin(2 pi f t) over one cycle: PGD = a / (2 pi f^2),
    CAV = 2 a / (pi f), Arias = pi a^2 / (4 g f). The pulse is sampled
    finely enough for its own frequency (800 samples a cycle at least), not
    on a fixed grid that a short pulse falls through."""
    a = 3.0
    pulse = jr.SinePulse(a, frequency)
    exact = {
        "pgd": a / (2 * np.pi * frequency**2),
        "cav": 2 * a / (np.pi * frequency),
        "arias": np.pi * a**2 / (4 * 9.81 * frequency),
    }
    for name, value in exact.items():
        assert float(jr.intensity_measure(pulse, name)) == pytest.approx(
            value, rel=2e-5
        ), name


def test_pga_ignores_samples_past_the_length():
    t = np.arange(0.0, 3.0, 0.01)
    a = 3.0 * np.sin(2 * np.pi * t)
    padded = a.copy()
    padded[200:] = 50.0
    own, long = jr.Record(a[:200], 0.01), jr.Record(padded, 0.01, length=200)
    assert float(jr.intensity_measure(long, "pga")) == float(
        jr.intensity_measure(own, "pga")
    )
    assert float(long.pga) == float(own.pga) == 3.0
    np.testing.assert_allclose(
        jr.intensity_measure(long, "pga_ratio", slenderness=4.0),
        jr.intensity_measure(own, "pga_ratio", slenderness=4.0),
    )
    assert float(long.scaled_to(pga=6.0).factor) == float(own.scaled_to(pga=6.0).factor)
    # A suite whose second row is padded by another record's longer tail.
    suite = jr.Record(
        np.stack([padded, padded]), np.array([0.01, 0.01]), length=np.array([300, 200])
    )
    np.testing.assert_array_equal(jr.intensity_measure(suite, "pga"), [50.0, 3.0])


def _fine_peaks(pulse, start, stop):
    t = np.linspace(start, stop, 400001)
    return (
        np.abs(np.asarray(pulse.acceleration(t))).max(),
        np.abs(np.asarray(pulse.velocity(t))).max(),
    )


def test_pga_pgv_of_a_long_mp_pulse():
    for gamma in (3000.0, 1e4):
        pulse = jr.MPPulse(0.5, 1.0, gamma, 30.0)
        t0 = float(pulse.t0)
        pga, pgv = _fine_peaks(pulse, t0 - 2.0, t0 + 2.0)
        np.testing.assert_allclose(jr.intensity_measure(pulse, "pga"), pga, rtol=1e-5)
        np.testing.assert_allclose(jr.intensity_measure(pulse, "pgv"), pgv, rtol=1e-5)
    # A batch, one of which starts before t = 0 (its peaks read from t = 0).
    pulses = jr.MPPulse(0.5, 1.0, np.array([2.0, 1e4]), 30.0, t0=np.array([0.3, 2.0]))
    got = jr.intensity_measure(pulses, "pga")
    one = jr.MPPulse(0.5, 1.0, 2.0, 30.0, t0=0.3)
    np.testing.assert_allclose(
        got[0], _fine_peaks(one, 0.0, float(one.end_time))[0], rtol=1e-6
    )
    big = jr.MPPulse(0.5, 1.0, 1e4, 30.0, t0=2.0)
    np.testing.assert_allclose(got[1], _fine_peaks(big, 0.0, 6.0)[0], rtol=1e-5)
