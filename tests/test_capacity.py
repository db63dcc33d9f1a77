"""An isolator's displacement capacity: `capacity=D` on any isolator ends
an analysis whose base passes D with `Status.CAPACITY_EXCEEDED`, without
changing its numbers (the isolator has no stop); maps count such cells and
fragility counts them in the isolator's displacement states only."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
LAM, SIZE = np.array([2.0, 4.0, 6.0]), np.array([0.5, 1.5, 3.0])
FIELDS = ("outcome", "max_rotation", "max_base_displacement", "impacts", "steps")


@pytest.mark.parametrize(
    "isolator",
    [
        lambda **limit: jr.LinearIsolator(2.0, 0.35, 0.5, **limit),
        lambda **limit: jr.FrictionPendulum(0.11, 2.24, 0.5, **limit),
    ],
    ids=["linear", "fps"],
)
def test_capacity_flags_cells_and_changes_nothing_else(isolator):
    plain = jr.behavior_map(LAM, SIZE, isolator(), PULSE)
    u = plain.max_base_displacement
    capacity = float(np.median(u))  # some cells pass it, some do not
    limited = isolator(capacity=capacity)
    bm = jr.behavior_map(LAM, SIZE, limited, PULSE)
    for k in FIELDS:
        np.testing.assert_array_equal(getattr(bm, k), getattr(plain, k))
    passed = (u >= capacity) & (plain.status == jr.Status.SUCCESS)
    assert 0 < passed.sum() < passed.size
    np.testing.assert_array_equal(bm.status == jr.Status.CAPACITY_EXCEEDED, passed)
    np.testing.assert_array_equal(bm.status[~passed], plain.status[~passed])
    assert bm.counts()["capacity_exceeded"] == passed.sum()
    assert "past the isolator's capacity" in bm.summary()
    i, j = np.argwhere(passed)[0]
    one = jr.simulate(jr.Block(LAM[i], SIZE[j]), limited, PULSE)
    assert int(one.status) == jr.Status.CAPACITY_EXCEEDED
    assert "hit its stop" in one.summary()


def test_fragility_counts_capacity_in_displacement_states_only():
    suite = jr.Record.stack(jr.records.fema_p695("nearfield_pulse")[:4])
    states = ["overturning", "displacement:0.1", "displacement:0.2"]
    base = jr.LinearIsolator(2.5, 0.2, 1.0)
    limited = jr.LinearIsolator(2.5, 0.2, 1.0, capacity=0.2)
    levels = np.array([0.5, 1.0, 2.0, 4.0])
    kwargs = dict(levels=levels, measure="pga", damage_states=states)
    plain = jr.fragility(3.0, 0.8, base, suite, **kwargs)
    frag = jr.fragility(3.0, 0.8, limited, suite, **kwargs)
    passed = frag.status == jr.Status.CAPACITY_EXCEEDED
    assert passed.any()
    # The displacement states count every analysis, as without a capacity.
    for state, column in (("displacement:0.1", 1), ("displacement:0.2", 2)):
        np.testing.assert_array_equal(frag.stripes(state)[1], plain.stripes(state)[1])
        np.testing.assert_array_equal(frag.stripes(state)[2], plain.stripes(state)[2])
        np.testing.assert_allclose(
            frag.median_damage[column], plain.median_damage[column], rtol=1e-12
        )
    # The block's states leave out the analyses past the capacity.
    _, _, counted = frag.stripes("overturning")
    _, _, all_of_them = plain.stripes("overturning")
    assert counted.sum() == all_of_them.sum() - passed.sum()


@pytest.mark.parametrize("bad", [0.0, -0.1, np.nan, np.inf])
def test_bad_capacity_is_refused(bad):
    with pytest.raises(ValueError, match="`capacity` must be finite and > 0"):
        jr.LinearIsolator(2.0, 0.35, 0.5, capacity=bad)


def test_fixed_base_takes_no_capacity():
    with pytest.raises(ValueError, match="a fixed base does not move"):
        jr.FixedBase(capacity=0.1)


def test_traced_bad_capacity_is_invalid_input():
    def status(capacity):
        base = jr.LinearIsolator(2.0, 0.35, 0.5, capacity=capacity)
        return jr.simulate(jr.Block(4.0, 1.0), base, PULSE).status

    assert int(jax.jit(status)(jnp.asarray(-1.0))) == jr.Status.INVALID_INPUT
    assert int(jax.jit(status)(jnp.asarray(10.0))) == jr.Status.SUCCESS


def test_cli_capacity_is_checked(capsys):
    from jaxrock.cli import main

    assert main(["map", "--base", "fixed", "--capacity", "0.2"]) == 2
    assert "--capacity and --stop-period are an isolator's" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["map", "--base", "linear", "--capacity", "-1"])
    assert "--capacity: must be finite and > 0" in capsys.readouterr().err


@pytest.mark.parametrize(
    "dish",
    [
        lambda radius, **kw: jr.FrictionPendulum(0.05, radius, 0.5, **kw),
        lambda radius, **kw: jr.SphericalRollingIsolator(radius, 0.005, 0.5, **kw),
    ],
    ids=["friction pendulum", "spherical rolling"],
)
def test_a_dish_s_slider_past_its_radius_exceeds_its_capacity(dish):
    """A friction pendulum's slider, or a rolling isolator's balls, cannot
    pass the radius R of their path: an analysis whose max |u| reaches R
    ends CAPACITY_EXCEEDED, with or without a `capacity`, where one that
    stays within R is SUCCESS."""
    samples = np.zeros(400)
    samples[100:102], samples[102:104] = 30.0, -30.0  # a 0.04 s kick, m/s^2
    kick = jr.Record(samples, 0.01)
    block = jr.Block(1.5, 1.0)  # too stocky to uplift on a friction pendulum
    wide = jr.simulate(block, dish(2.0), kick)
    assert wide.status == jr.Status.SUCCESS
    assert 0.0 < float(wide.max_base_displacement) < 0.5
    radius = 0.5 * float(wide.max_base_displacement)
    for capacity in (None, 10.0):
        narrow = jr.simulate(block, dish(radius, capacity=capacity), kick)
        assert narrow.status == jr.Status.CAPACITY_EXCEEDED
        assert float(narrow.max_base_displacement) >= radius
    assert dish(2.0).geometric_limit == 2.0
    assert jr.LinearIsolator(2.0, 0.35, 0.5).geometric_limit is None
