"""Bad input: a clear `ValueError` naming the parameter before anything runs,
or, inside compiled code, a status of its own and NaN results; never a
plausible number."""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _model
from jaxrock._scene import prepare

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
_RECORD = jr.Record(np.sin(2 * np.pi * np.arange(0.0, 10.0, 0.01)), 0.01)


# -- wrong results reported as normal -------------------------------------------


def test_zeno_sequence_without_rest_rule_never_rotates_past_overturning():
    """With `rest_tolerance=0` the impacts of this block accumulate (Zeno) and an
    apex is located at theta = 0 to rounding, on the wrong side; falling from
    there, the impact condition started <= 0 and never fired, and the block
    rotated to 17.6 alpha (past pi / 2) reported as ROCKING / SUCCESS."""
    block, pulse = (
        jr.Block(3.0, 3.0),
        jr.near_fault_pulse("San Fernando PCD/SN", scale=0.8),
    )
    tight = dict(rtol=1e-10, atol=1e-12)
    zeno = jr.simulate(block, jr.FixedBase(), pulse, rest_tolerance=0.0, **tight)
    assert int(zeno.outcome) == jr.Outcome.ROCKING
    assert float(zeno.max_rotation) < math.pi / 2 / float(block.alpha)
    assert int(zeno.status) in (jr.Status.SUCCESS, jr.Status.MAX_SEGMENTS)
    # A tight rest rule gives the same largest excursion (and the SciPy
    # reference agrees: 0.00143712 alpha at every rest_tolerance from 1e-4 down).
    rule = jr.simulate(block, jr.FixedBase(), pulse, rest_tolerance=1e-10, **tight)
    assert int(rule.status) == jr.Status.SUCCESS
    assert float(zeno.max_rotation) == pytest.approx(float(rule.max_rotation), rel=1e-6)


def test_rotation_past_overturning_without_the_event_is_a_failure():
    """The last line of defence: whatever missed an event, |theta| > pi / 2
    without overturning never comes back as SUCCESS."""
    block, base = jr.Block(3.0, 1.0), jr.FixedBase()
    c = _model.initial_carry(block, base, prepare(PULSE))
    lost = eqx.tree_at(
        lambda c: (c.max_theta, c.done), c, (jnp.asarray(2.0), jnp.asarray(True))
    )
    r = _model.response(lost, block, base, jr.SolverOptions())
    assert int(r.status) == jr.Status.SOLVER_FAILED
    assert int(r.outcome) != jr.Outcome.OVERTURNED


@pytest.fixture(scope="module")
def traced():
    """`simulate` on a linear isolator built from traced values (vmap + jit:
    one compile for every case)."""

    def one(slenderness, period, amplitude, rtol):
        block = jr.Block(slenderness, 1.0)
        base = jr.LinearIsolator(period, 0.35, 0.5)
        pulse = jr.MPPulse(amplitude, 0.68, 1.6, 180.0)
        return jr.simulate(block, base, pulse, rtol=rtol)

    cases = {
        "valid": (4.0, 2.0, 1.15, 1e-8),
        "nan slenderness": (np.nan, 2.0, 1.15, 1e-8),
        "negative slenderness": (-4.0, 2.0, 1.15, 1e-8),
        "huge slenderness": (1.4e154, 2.0, 1.15, 1e-8),
        "negative period": (4.0, -2.0, 1.15, 1e-8),
        "nan amplitude": (4.0, 2.0, np.nan, 1e-8),
        "negative rtol": (4.0, 2.0, 1.15, -1e-8),
    }
    columns = [jnp.asarray(c) for c in zip(*cases.values())]
    r = jax.jit(jax.vmap(one))(*columns)
    return {
        name: jax.tree_util.tree_map(lambda x: x[i], r) for i, name in enumerate(cases)
    }


@pytest.mark.parametrize(
    "case",
    [
        "nan slenderness",
        "negative slenderness",
        "huge slenderness",
        "negative period",
        "nan amplitude",
        "negative rtol",
    ],
)
def test_traced_invalid_parameters_give_invalid_input_and_nan(traced, case):
    r = traced[case]
    assert int(r.status) == jr.Status.INVALID_INPUT
    assert not r.ok
    assert np.isnan(float(r.max_rotation))
    assert np.isnan(float(r.max_base_displacement))
    assert int(r.outcome) == jr.Outcome.NO_ROCKING and int(r.steps) == 0
    assert "INVALID_INPUT" in r.summary()


def test_traced_valid_parameters_are_unaffected(traced):
    r = traced["valid"]
    direct = jr.simulate(
        jr.Block(4.0, 1.0),
        jr.LinearIsolator(2.0, 0.35, 0.5),
        jr.MPPulse(1.15, 0.68, 1.6, 180.0),
    )
    assert int(r.status) == jr.Status.SUCCESS
    assert float(r.max_rotation) == pytest.approx(float(direct.max_rotation), rel=1e-12)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: jr.Block(1.4e154, 1.0), "`slenderness` must be finite, >= 0.01"),
        (lambda: jr.Block(4.0, 1e-9), "`size` must be finite, >= 0.001"),
        (lambda: jr.Block("4.0", 1.0), "`slenderness` must be a real number"),
        (lambda: jr.Block(True, 1.0), "`slenderness` must be a real number"),
        (lambda: jr.Block(4.0, None), "`size` must be a real number"),
        (lambda: jr.LinearIsolator(2.0, 1 + 2j, 0.5), "`damping` must be a real"),
        # A base 1e300 times lighter than its block: e0 was NaN, named as f.
        (lambda: jr.LinearIsolator(2.0, 0.1, 1e300), "`mass_ratio` must be finite, >"),
        (lambda: jr.FrictionPendulum(0.1, 2.0, 1e7), r"<= 1e\+06, got 1"),
        (lambda: jr.Record(np.zeros(9), 0.01, azimuth=np.nan), "`azimuth` must be"),
        # Beyond any ground motion (its Arias intensity overflowed to NaN).
        (lambda: jr.Record([0, 1e300, 0], 0.01), r"within \+-100000 m/s\^2"),
        (lambda: _RECORD.scaled(1e308), r"`factor` must be finite, > 0 and <= 1e\+06"),
        (
            lambda: jr.eurocode8_spectrum([1.0], 2.0, spectrum_type=True),
            "`spectrum_type` must be 1 or 2",
        ),
        # A stop's parameters, apart from its isolator's own period and damping.
        (lambda: jr.Stop(0.05, 1.0), "`Stop.damping` must be finite, >= 0 and < 1"),
        (lambda: jr.Stop(-0.05), "`Stop.period` must be finite and > 0"),
        (lambda: jr.MPPulse(1.0, 0.5, 2.0, 0.0, t0=-10.0), "`t0` must be > -gamma"),
        (lambda: jr.SolverOptions(max_steps=2.5), "`max_steps` must be an integer"),
        (lambda: jr.fit_lognormal([1.0, 2.0], [True]), "`im` and `failed`"),
        (lambda: jr.fit_lognormal([1, 2, 3], [0, np.nan, 1]), "`failed` must be"),
        (lambda: jr.fit_lognormal([1, 2, 3], [0, 2, 1]), "booleans"),
        (
            lambda: jr.fit_lognormal([1, 2, 3], [0, 1, 1], trials=[1, 2]),
            "`trials` must be one number or one per level",
        ),
        (lambda: jr.near_fault_pulse("Tabas TAB/SP", scale=-1.0), "`scale` must be"),
        # An empty batch: no analysis to run (it failed inside a map).
        (lambda: jr.LinearIsolator(np.array([]), 0.1, 0.5), "`period` must hold"),
        (lambda: jr.MPPulse(np.array([]), 0.5, 2.0, 0.0), "`amplitude` must hold"),
        (
            lambda: jr.FrictionPendulum(0.1, 2.0, 0.5, capacity=np.array([])),
            "`capacity` must hold at least one value",
        ),
        (
            lambda: jr.design.isolator_objective(
                lambda p: jr.LinearIsolator(p["period"], 0.35, 0.5),
                jr.Block(4.0, 1.0),
                PULSE,
                capacity=0.0,
            ),
            "`capacity` must be finite and > 0",
        ),
    ],
)
def test_bad_values_name_the_parameter(make, message):
    with pytest.raises(ValueError, match=message):
        make()


# -- API errors that must be a ValueError naming the parameter -------------------


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: jr.behavior_map([], [1.0], jr.FixedBase(), PULSE), "`slenderness`"),
        (lambda: jr.behavior_map([4.0], [], jr.FixedBase(), PULSE), "`size`"),
        (lambda: jr.behavior_map(["a"], [1.0], jr.FixedBase(), PULSE), "`slenderness`"),
        (
            lambda: jr.behavior_map(
                [4.0], [1.0], jr.FixedBase(), PULSE, chunk_size=2.5
            ),
            "`chunk_size`",
        ),
        (
            lambda: jr.behavior_map([4.0], [1.0], jr.FixedBase(), PULSE, store=""),
            "`store`",
        ),
        (
            lambda: jr.behavior_map(
                np.linspace(1, 7, 100000),
                np.linspace(0.1, 4, 10000),
                jr.FixedBase(),
                PULSE,
            ),
            "cells",
        ),
        (lambda: jr.simulate(None, jr.FixedBase(), PULSE), "`block`"),
        (lambda: jr.simulate(jr.Block(3.0, 1.0), "fixed", PULSE), "`base`"),
        (lambda: jr.simulate(jr.Block(3.0, 1.0), jr.FixedBase(), 1.0), "`motion`"),
        (
            lambda: jr.simulate(jr.Block([3.0, 4.0], 1.0), jr.FixedBase(), PULSE),
            "`block` must hold one value",
        ),
        (
            lambda: jr.simulate(
                jr.Block(3.0, 1.0), jr.FixedBase(), PULSE, history=True, history_step=0
            ),
            "`history_step`",
        ),
        (  # ten billion rows: named before any memory is taken
            lambda: jr.simulate(
                jr.Block(3.0, 1.0),
                jr.FixedBase(),
                PULSE,
                history=True,
                history_step=1e-9,
            ),
            r"`history_step` must be >= the window / 10,000,000",
        ),
        # Spectra's periods: shorter ones take memory as 1 / T, longer a tail.
        (lambda: jr.response_spectrum(PULSE, [1e-9, 1.0]), r"`periods`.*0\.001, 100"),
        (lambda: jr.response_spectrum(PULSE, 1e3), r"`periods` must be in"),
        (lambda: jr.intensity_measure(PULSE, "sa:1e-9"), r"`measure`.*0\.001, 100"),
        (lambda: jr.intensity_measure(PULSE, "sa:1e9"), r"`measure`"),
        (
            lambda: jr.overturning_spectrum(
                jr.Block(3.0, 1.0), jr.FixedBase(), [], [1.0]
            ),
            "`frequency_ratio`",
        ),
        (
            lambda: jr.overturning_spectrum(
                jr.Block(3.0, 1.0),
                jr.LinearIsolator([1.5, 2.0], 0.35, 0.5),
                [1.0],
                [2.0],
            ),
            "`base` must be one base",
        ),
        (
            lambda: jr.fragility(
                3.0, 1.0, jr.LinearIsolator([1.5, 2.0], 0.35, 0.5), PULSE, scales=[1.0]
            ),
            "`base` must be one base",
        ),
        (lambda: jr.simulate(jr.Block(3.0, 1.0), None, PULSE), "`base` must be an iso"),
        (
            lambda: jr.simulate(jr.Block(3.0, 1.0), jr.FixedBase(), np.ones(3)),
            "`motion` must be a ground motion",
        ),
        (
            lambda: jr.simulate(
                jr.Block(3.0, 1.0), jr.FixedBase(), PULSE, solver=diffrax.Euler()
            ),
            "`solver` must be an adaptive Diffrax solver",
        ),
        (
            lambda: jr.simulate(
                jr.Block(3.0, 1.0), jr.FixedBase(), PULSE, solver=diffrax.Tsit5
            ),
            "`solver` must be",
        ),
        (
            lambda: jr.simulate(jr.Block(3.0, 1.0), jr.FixedBase(), PULSE, history="y"),
            "`history` must be True or False",
        ),
        (
            lambda: jr.simulate(
                jr.Block(3.0, 1.0), jr.FixedBase(), PULSE, history_step=0.01
            ),
            "`history_step` is read only with `history=True`",
        ),
        (
            lambda: jr.overturning_spectrum(
                jr.Block(np.array([3.0, 4.0]), 1.0), jr.FixedBase(), [1.0], [1.0]
            ),
            "`block` must be one block",
        ),
        (
            lambda: jr.fragility(
                np.array([3.0, 4.0]), 1.0, jr.FixedBase(), PULSE, scales=[1.0, 2.0]
            ),
            "`slenderness` must be one number, finite and > 0",
        ),
        # A target of another shape than the records'.
        (lambda: _RECORD.scaled_to(pga=[1.0, 2.0]), "`pga` must be one number or"),
        (
            lambda: jr.Record.stack([_RECORD, _RECORD]).scaled_to(pgv=[1, 2, 3]),
            r"one per record, of shape \(2,\), got shape \(3,\)",
        ),
    ],
)
def test_api_errors_are_value_errors_naming_the_parameter(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def _tune(**overrides):
    kwargs = dict(
        make_base=lambda p: jr.LinearIsolator(p["period"], 0.35, 0.5),
        init={"period": 2.0},
        blocks=jr.Block(jnp.array([4.0]), jnp.array([1.0])),
        motions=PULSE,
        bounds={"period": (1.0, 3.0)},
        steps=0,
    )
    kwargs.update(overrides)
    return jr.design.tune_isolator(**kwargs)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (dict(capacity=-1.0), "`capacity` must be finite and > 0"),
        (dict(capacity=0.0), "`capacity` must be finite and > 0"),
        (dict(capacity=float("nan")), "`capacity` must be finite"),
        (dict(penalty=-10.0), "`penalty` must be finite and >= 0"),
        (dict(learning_rate=-1.0), "`learning_rate` must be finite and > 0"),
        (dict(learning_rate=float("nan")), "`learning_rate` must be finite"),
        (dict(steps=-1), "`steps` must be an integer >= 0"),
        (dict(init={}), "`init` must be a non-empty dict"),
        (dict(bounds={"period": (1.0, float("inf"))}), r"bounds\['period'\]"),
        (dict(make_base=lambda p: jr.FixedBase()), "`make_base` must return"),
        (
            dict(blocks=jr.Block(3.0 * jnp.ones((2, 2)), 0.5)),
            r"`blocks` must have one batch axis \(n_blocks\) or none, got shape",
        ),
        # An isolator that does not exist at an end of the bounds.
        (
            dict(bounds={"period": (0.0, 3.0)}),
            r"bounds\['period'\]: `make_base` fails at its low end: `period` must",
        ),
    ],
)
def test_tune_isolator_checks_its_arguments(overrides, message):
    with pytest.raises(ValueError, match=message):
        _tune(**overrides)


def test_fragility_names_a_zero_amplitude_motion():
    motions = jr.MPPulse(jnp.array([0.0, 1.0]), 0.5, 2.0, 0.0)
    with pytest.raises(ValueError, match="`motions`.*zero amplitude"):
        jr.fragility(4.0, 1.0, jr.FixedBase(), motions)


# -- BehaviorMap.load ------------------------------------------------------------


def test_history_is_sampled_by_time_not_by_count():
    """A long analysis keeps its time resolution: samples every `history_step`
    (default: duration / 2000, at most 0.01 s), besides every event."""
    block, base = jr.Block(4.0, 1.0), jr.FixedBase()
    long = jr.simulate(block, base, PULSE, history=True, duration=400.0)
    regular = np.diff(long.history.t)
    assert regular.max() <= 0.01 + 1e-12
    assert long.history.t.size >= long.history.t[-1] / 0.01  # every 0.01 s
    fine = jr.simulate(block, base, PULSE, history=True, history_step=0.002)
    assert np.diff(fine.history.t).max() <= 0.002 + 1e-12
    assert float(fine.max_rotation) == float(long.max_rotation)


# -- a record's dt and simulate's duration ----------------------------------------

SAMPLES = 5.0 * np.sin(0.1 * np.arange(1000))  # m/s^2: uplifts a Block(4.0, 1.0)


@pytest.mark.parametrize("dt", [1e-300, 1e-7, 1.5, 1e308, float("inf")])
def test_record_dt_out_of_range_names_dt_and_the_range(dt):
    # At dt = 1e-300 the whole record is shorter than the event tolerance
    # (1e-12 s): it gave ROCKING, SUCCESS and a max rotation of exactly 0; at
    # 1e308 the end time is inf, and `simulate` blamed `duration`.
    with pytest.raises(
        ValueError, match=r"`dt` must be finite, >= 1e-06 and <= 1 \(s\)"
    ):
        jr.Record(SAMPLES, dt)


def test_traced_record_dt_out_of_range_is_invalid():
    valid = jax.jit(lambda dt: jr.Record(SAMPLES, dt).valid())
    assert bool(valid(0.01)) and bool(valid(1e-6)) and bool(valid(1.0))
    assert not bool(valid(1e-300)) and not bool(valid(1e308))


def test_uplift_at_the_smallest_dt_is_located_as_at_a_usual_one():
    """On a fixed base a block uplifts where |x_g''| first reaches g tan alpha:
    at the same fraction of the record whatever its dt. At dt = 1e-6 s (the
    lower end of the range) the uplift is found there to 1e-6 of a sample
    interval; at 1e-12 s it was 0.9 of one off (the event tolerance)."""
    block = jr.Block(4.0, 1.0)
    run = jax.jit(
        lambda dt: jr.simulate(block, jr.FixedBase(), jr.Record(SAMPLES, dt)),
    )
    usual, smallest = run(0.01), run(1e-6)
    assert int(usual.status) == int(smallest.status) == jr.Status.SUCCESS
    in_samples = float(usual.uplift_time) / 0.01
    assert float(smallest.uplift_time) / 1e-6 == pytest.approx(in_samples, abs=1e-6)


@pytest.mark.parametrize(
    "duration, message",
    [
        ([10.0], r"`duration` must be one number, finite and > 0 \(s\), got an array"),
        (np.ones((1, 1)), r"`duration` must be one number.*shape \(1, 1\)"),
        ("10", "`duration` must be a real number"),
    ],
)
def test_duration_that_is_not_one_number_is_named(duration, message):
    with pytest.raises(ValueError, match=message):
        jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(), PULSE, duration=duration)


def test_a_maps_duration_that_is_not_one_number_is_named():
    with pytest.raises(ValueError, match="`duration` must be one number"):
        jr.behavior_map([4.0], [1.0], jr.FixedBase(), PULSE, duration=[10.0])


def test_a_member_of_a_batch_is_labelled_by_its_parameters():
    """`select` names the pulse (or isolator) it picks, not the whole batch."""
    pulses = jr.MPPulse(np.array([1.0, 2.0]), 1.0, 2.0, 0.0)
    bm = jr.behavior_map([3.0], [1.0], jr.FixedBase(), pulses, progress=False)
    assert bm.select(1).motion == f"{bm.motion} [amplitude = 2 m/s]"
    assert bm.select(1).base == bm.base
    assert bm.select(-1).motion == bm.select(1).motion
    for index in (2, -3, True, None, 1.0, "A", slice(0, 1), [0, 1]):
        with pytest.raises(
            ValueError, match=r"`index` must be an integer in \[-2, 2\)"
        ):
            bm.select(index)


def test_history_step_that_is_not_one_number_is_named():
    with pytest.raises(ValueError, match="`history_step` must be one number"):
        jr.simulate(
            jr.Block(4.0, 1.0), jr.FixedBase(), PULSE, history=True, history_step=[0.1]
        )


@pytest.mark.parametrize("name", ["rtol", "atol", "rest_tolerance"])
def test_map_and_simulate_refuse_tolerance_arrays(name):
    value = {
        "rtol": [1e-8, 1e-6],
        "atol": [1e-10, 1e-9],
        "rest_tolerance": [1e-6, 1e-5],
    }
    with pytest.raises(ValueError, match=f"`{name}` must be one number"):
        jr.behavior_map(
            [4.0], [1.0], jr.FixedBase(), PULSE, progress=False, **{name: value[name]}
        )
    with pytest.raises(ValueError, match=f"`{name}` must be one number"):
        jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(), PULSE, **{name: value[name]})
