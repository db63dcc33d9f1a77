"""`jaxrock.design`: its analyses are `simulate`'s (a long record's step
limit, the status of each analysis), and its inputs are checked as
`simulate` checks them."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrock as jr


def _long_record():
    """20,000 samples: a weak start, then nothing new for 18,000 samples
    (one segment of more steps than `MAX_STEPS`), then a pulse at 190 s."""
    dt, n = 0.01, 20000
    t = np.arange(n) * dt
    rng = np.random.default_rng(0)
    late = (t > 190.0) & (t < 191.0)
    ground = 0.5 * np.exp(-t / 2.0) * rng.standard_normal(n)
    return jr.Record(ground + 4.0 * np.sin(2 * np.pi * (t - 190.0)) * late, dt)


def test_design_analyses_a_long_record_as_simulate_does():
    """`responses` (so the objective and `tune_isolator`) raise the step
    limit for a long record as `simulate` does, and `DesignResult` keeps
    each analysis's status."""
    record, block = _long_record(), jr.Block(4.0, 1.0)
    one = jr.simulate(block, jr.LinearIsolator(2.0, 0.2, 0.5), record)
    assert bool(one.ok) and int(one.outcome) == jr.Outcome.OVERTURNED
    res = jr.design.tune_isolator(
        lambda p: jr.LinearIsolator(p["period"], 0.2, 0.5),
        {"period": 2.0},
        block,
        record,
        bounds={"period": (1.0, 3.0)},
        steps=0,
    )
    assert res.status.shape == (1, 1, 1)
    assert np.all(res.status == jr.Status.SUCCESS)
    assert res.max_rotation[0, 0, 0] == pytest.approx(float(one.max_rotation))


def test_tune_isolator_checks_restitution_on_the_base():
    """f e0 <= 1 depends on the base: checked as `simulate` checks it, with
    the parameter named, not a NaN objective and a NaN period later."""
    with pytest.raises(ValueError, match="restitution_factor"):
        jr.design.tune_isolator(
            lambda p: jr.LinearIsolator(p["period"], 0.2, 0.5),
            {"period": 2.0},
            jr.Block(jnp.array([4.0, 6.0]), 1.0, restitution_factor=1.5),
            jr.MPPulse(0.8, 1.0, 2.0, 0.0),
            bounds={"period": (1.0, 3.0)},
            steps=2,
        )


@pytest.mark.parametrize(
    "blocks, motions, message",
    [
        (4.0, jr.MPPulse(1.0, 1.0, 2.0, 0.0), "`blocks` must be a Block"),
        (jr.Block(4.0, 1.0), 3.0, "`motions` must be a ground motion"),
        (
            jr.Block(4.0, 1.0),
            jr.MPPulse(jnp.ones((2, 2)), 1.0, 2.0, 0.0),
            "`motions` must have one batch axis",
        ),
        (
            jr.Block(4.0, 1.0),
            jr.MPPulse(jnp.ones(2), jnp.ones(3), 2.0, 0.0),
            "must share one batch shape",
        ),
        (
            jr.Block(jnp.ones((2, 2)) * 4.0, 1.0),
            jr.MPPulse(1.0, 1.0, 2.0, 0.0),
            "`blocks` must have one batch axis",
        ),
    ],
)
def test_design_names_blocks_and_motions_it_cannot_pair(blocks, motions, message):
    """Blocks and motions are paired before anything compiles; what cannot be
    paired is named (not a broadcast error from inside JAX)."""
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    with pytest.raises(ValueError, match=message):
        jr.design.responses(base, blocks, motions)


def _row(period, objective, status):
    """A row of `_descend`: one iterate with one analysis of `status`."""
    shape = (1, 1)
    return (
        {"period": period},
        objective,
        {"period": 0.0},
        np.zeros(shape),
        np.zeros(shape),
        np.zeros(shape, bool),
        np.full(shape, int(status)),
    )


def test_design_s_best_skips_iterates_whose_analyses_are_not_final():
    """An iterate with an analysis that stopped short (its J is not final) is
    never `best`, even at the lowest J, and a warning names it; with no final
    iterate the lowest J stands, with the warning."""
    from jaxrock._design import _design_result

    rows = [
        _row(1.0, 0.3, jr.Status.SUCCESS),
        _row(2.0, 0.01, jr.Status.MAX_STEPS),
        _row(3.0, 0.2, jr.Status.CAPACITY_EXCEEDED),
    ]
    with pytest.warns(UserWarning, match=r"1 of 3 analyses .*MAX_STEPS.*\[1\]"):
        res = _design_result(rows, ["period"])
    assert res.best == {"period": 3.0}
    with pytest.warns(UserWarning, match="`best` is not"):
        res = _design_result(rows[1:2], ["period"])
    assert res.best == {"period": 2.0}
