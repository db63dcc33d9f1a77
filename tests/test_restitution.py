"""A coefficient of restitution set by the user: `Block(..., restitution_factor=f)`
applies e = f e0 at a re-uplift (e0 the momentum model's, Eq. 2.13), and
`Block(..., restitution=e)` applies e itself.

Against the independent SciPy reference (tests/reference.py, which applies e
and the conservation of M u' + m h theta' on its own), at rtol 1e-10 /
atol 1e-12 on both sides as in test_reference.py: the same outcome and impact
count, max rotation and max base displacement within 1e-6 relative. f = 1 is
the momentum model to the bit; derivatives in f against central differences.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference as ref
from test_reference import BASES, _pulse

import jaxrock as jr
from jaxrock._dynamics import impact, momentum_restitution, restitution

TOL = dict(rtol=1e-10, atol=1e-12)

# (base, pulse, slenderness, size, amplitude scale, f or ("e", e)): many
# impacts and overturning (after several impacts) on each base, with f e0 <= 1.
CASES = [
    ("fixed", "Aigion AEG/Lon", 2.5, 0.8, 1.5, 0.8),  # rocks, 14 impacts
    ("fixed", "Aigion AEG/Lon", 2.5, 0.8, 1.5, 1.1),  # rocks, 45 impacts
    ("fixed", "San Fernando PCD/SN", 2.5, 0.3, 1.0, 1.1),  # overturns, 4 impacts
    ("fixed", "San Fernando PCD/SN", 6.0, 2.0, 1.0, 0.8),  # rocks, 25 impacts
    ("linear", "San Fernando PCD/SN", 3.0, 0.5, 1.0, 0.8),  # rocks, 16 impacts
    ("linear", "San Fernando PCD/SN", 3.0, 0.5, 1.0, 1.1),  # rocks, 52 impacts
    ("linear", "Bucharest BRI/SN", 3.0, 0.5, 1.6, 0.8),  # overturns, 11 impacts
    ("linear", "Bucharest BRI/SN", 3.0, 0.8, 1.6, 1.1),  # overturns, 20 impacts
    ("linear", "Bucharest BRI/SN", 4.0, 0.6, 1.0, ("e", 0.7)),  # e given
    ("fps", "San Fernando PCD/SN", 4.0, 1.0, 1.0, 0.8),  # rocks, 13 impacts
    ("fps", "Imperial Valley E05/SN", 4.0, 2.5, 1.5, 1.1),  # rocks, 98 impacts
]


def _block(lam, r, f):
    if isinstance(f, tuple):
        return jr.Block(lam, r, restitution=f[1])
    return jr.Block(lam, r, restitution_factor=f)


def _reference(key, name, lam, r, scale, f):
    _, ref_base = BASES[key]
    _, (acc, t_end, max_step) = _pulse(name, scale)
    given = (
        dict(restitution=f[1]) if isinstance(f, tuple) else dict(restitution_factor=f)
    )
    return ref.simulate(lam, r, ref_base, acc, t_end + 5.0, max_step, **given)


@pytest.mark.parametrize("case", CASES, ids=str)
def test_matches_reference(case):
    key, name, lam, r, scale, f = case
    motion, (_, t_end, _) = _pulse(name, scale)
    window = TOL | dict(duration=t_end + 5.0)  # the reference's
    ours = jr.simulate(_block(lam, r, f), BASES[key][0], motion, **window)
    theirs = _reference(*case)
    assert int(ours.status) == jr.Status.SUCCESS
    assert int(ours.outcome) == theirs["outcome"]
    assert int(ours.impacts) == theirs["impacts"]
    assert theirs["impacts"] >= 4  # many impacts, not a single one
    np.testing.assert_allclose(
        float(ours.max_rotation), theirs["max_rotation"], rtol=1e-6
    )
    np.testing.assert_allclose(
        float(ours.max_base_displacement),
        theirs["max_base_displacement"],
        rtol=1e-6,
        atol=1e-12,
    )


def test_cases_rock_and_overturn_on_each_isolator():
    outcomes = {(c[0], _reference(*c)["outcome"]) for c in CASES if c[0] != "fps"}
    assert {("fixed", 1), ("fixed", 2), ("linear", 1), ("linear", 2)} <= outcomes


@pytest.mark.parametrize("key", ["fixed", "linear", "fps"])
def test_factor_one_is_the_momentum_model_to_the_bit(key):
    """(The engine before `restitution_factor` existed gave these responses,
    and a map of 120 cells on each base, to the bit: measured once.)"""
    base = BASES[key][0]
    motion, _ = _pulse("San Fernando PCD/SN", 1.0)
    lam, r = {"fixed": (6.0, 2.0), "linear": (3.0, 0.5), "fps": (4.0, 1.0)}[key]
    default = jr.simulate(jr.Block(lam, r), base, motion)
    one = jr.simulate(jr.Block(lam, r, restitution_factor=1.0), base, motion)
    for a, b in zip(jax.tree_util.tree_leaves(default), jax.tree_util.tree_leaves(one)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert int(default.impacts) >= 2


@pytest.mark.parametrize("key", ["fixed", "linear", "fps"])
def test_jump_map_conserves_momentum_and_is_eq_2_14_at_factor_one(key):
    base = BASES[key][0]
    mu = float(base.block_mass_fraction)
    theta_dot = -0.37
    state = None if key == "fixed" else base.initial_state().at[1].set(0.21)
    for f in (0.5, 0.8, 1.0, 1.05):
        block = jr.Block(4.0, 1.2, restitution_factor=f)
        e0, den = momentum_restitution(block, base)
        post, post_state = impact(block, base, jnp.asarray(theta_dot), state, False)
        assert float(post) == float(f * e0) * theta_dot
        if state is None:
            continue
        h = float(block.h)
        # per unit M: u' + mu h theta' before and after.
        before = 0.21 + mu * h * theta_dot
        np.testing.assert_allclose(
            float(post_state[1]) + mu * h * float(post), before, rtol=1e-15
        )
        if f == 1.0:  # Eq. 2.14: u'+ = u'- + 6 m h b^2 theta'- / den, to the bit
            kick = 6.0 * (mu / (1.0 - mu)) * block.h * block.b**2 / den
            assert float(post_state[1]) == float(0.21 + kick * theta_dot)


def test_coefficient_given_directly():
    base = BASES["linear"][0]
    block = jr.Block(4.0, 1.0, restitution=0.6)
    e, _ = restitution(block, base)
    assert float(e) == 0.6
    assert block.restitution_factor is None
    e1, _ = restitution(jr.Block(4.0, 1.0, restitution_factor=0.9), base)
    e0, _ = momentum_restitution(jr.Block(4.0, 1.0), base)
    assert float(e1) == 0.9 * float(e0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(restitution_factor=0.0), "`restitution_factor` must be finite and > 0"),
        (dict(restitution_factor=-1.0), "`restitution_factor` must be finite"),
        (dict(restitution_factor=float("nan")), "`restitution_factor` must be"),
        (dict(restitution_factor=float("inf")), "`restitution_factor` must be"),
        (dict(restitution=1.2), "`restitution` must be finite, >= 0 and <= 1"),
        (dict(restitution=-0.1), "`restitution` must be finite, >= 0 and <= 1"),
        (dict(restitution_factor=0.9, restitution=0.5), "not both"),
        (dict(restitution_factor="1"), "`restitution_factor` must be a real number"),
    ],
)
def test_bad_coefficients_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jr.Block(4.0, 1.0, **kwargs)


def test_factor_above_one_over_e0_is_refused_naming_the_base():
    motion, _ = _pulse("San Fernando PCD/SN", 1.0)
    # Fixed base, lambda 4: e0 = 0.912, f <= 1.097; on the linear isolator
    # (mass ratio 0.5) e0 = 0.885: f = 1.1 passes there and not here.
    jr.simulate(jr.Block(4.0, 1.0, restitution_factor=1.1), BASES["linear"][0], motion)
    with pytest.raises(ValueError) as info:
        jr.simulate(jr.Block(4.0, 1.0, restitution_factor=1.1), jr.FixedBase(), motion)
    message = str(info.value)
    assert "`restitution_factor`" in message and "mass ratio" in message
    assert "f must be <= 1.097" in message


def test_factor_above_one_over_e0_traced_is_an_invalid_input():
    motion, _ = _pulse("San Fernando PCD/SN", 1.0)

    @jax.jit
    def run(f):
        return jr.simulate(
            jr.Block(4.0, 1.0, restitution_factor=f), jr.FixedBase(), motion
        )

    assert int(run(1.2).status) == jr.Status.INVALID_INPUT
    assert np.isnan(float(run(1.2).max_rotation))
    assert int(run(1.05).status) == jr.Status.SUCCESS


GRAD_TOL = dict(rtol=1e-12, atol=1e-14)


def _response(key, f):
    lam, r, name, scale = (
        (2.5, 0.8, "Aigion AEG/Lon", 1.5)
        if key == "fixed"
        else (
            3.0,
            0.5,
            "San Fernando PCD/SN",
            1.0,
        )
    )
    motion, _ = _pulse(name, scale)
    block = jr.Block(lam, r, restitution_factor=f)
    return jr.simulate(block, BASES[key][0], motion, **GRAD_TOL)


@functools.cache
def _derivative(key, f0, field):
    d = jax.jacfwd(lambda f: getattr(_response(key, f), field))(jnp.asarray(f0))
    return float(d)


@pytest.mark.parametrize(
    "key, field",
    # (the linear isolator's impacts change theta' and u': both kicks)
    [("linear", "max_rotation")],
)
def test_jacfwd_in_factor_matches_central_differences(key, field):
    """Central differences with a relative step of 1e-5, both at rtol 1e-12
    (solver noise ~1e-7 relative), where the impact count and outcome stay the
    same inside the stencil (test_gradients.py)."""
    f0 = 0.9
    h = 1e-5 * f0
    lo, mid, hi = _response(key, f0 - h), _response(key, f0), _response(key, f0 + h)
    assert int(mid.impacts) >= 2
    for r in (lo, hi):
        assert int(r.impacts) == int(mid.impacts) and int(r.outcome) == int(mid.outcome)
    fd = (float(getattr(hi, field)) - float(getattr(lo, field))) / (2 * h)
    assert abs(fd) > 1e-6  # max rotation after an impact: it depends on f
    assert _derivative(key, f0, field) == pytest.approx(fd, rel=1e-5)


@pytest.mark.parametrize("value", ["0", "-0.5", "nan", "1.2"])
@pytest.mark.parametrize("command", ["simulate", "map"])
def test_cli_refuses_a_bad_factor_in_one_line(command, value, capsys, tmp_path):
    from jaxrock import cli

    if command == "simulate":
        argv = ["simulate", "--base", "fixed", "--slenderness", "6", "--size", "2"]
    else:
        argv = ["map", "--base", "fixed", "--slenderness", "2:6:3", "--size", "1:2:2"]
    argv += ["--restitution-factor", value, "--out", str(tmp_path / "r.png")]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "restitution_factor" in err


def test_a_map_takes_a_batch_of_factors_as_an_axis():
    """`behavior_map(..., restitution_factor=[...])`: an axis after the
    motions', each member the map of blocks with that factor, cell by cell
    the analysis of `simulate`; f = 1 is the default map to the bit; a
    coefficient given directly is one value for every block; a factor that
    makes f e0 > 1 for a slenderness of the grid is refused before any
    compile."""
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    lam, size, base = [3.0, 5.0, 7.0], [0.5, 1.5], jr.FixedBase()
    factors = np.array([0.8, 1.0])
    bm = jr.behavior_map(lam, size, base, pulse, restitution_factor=factors)
    assert bm.outcome.shape == (2, 3, 2)
    assert bm.coordinates.dims == ("restitution_factor",)
    plain = jr.behavior_map(lam, size, base, pulse)
    for k in ("outcome", "max_rotation", "impacts", "segments", "steps"):
        np.testing.assert_array_equal(getattr(bm, k)[1], getattr(plain, k), k)
    assert np.any(bm.impacts[0] != bm.impacts[1])  # the factor changes the map
    for i, j in np.ndindex(3, 2):
        one = jr.simulate(
            jr.Block(lam[i], size[j], restitution_factor=0.8), base, pulse
        )
        assert bm.outcome[0, i, j] == int(one.outcome)
        assert bm.impacts[0, i, j] == int(one.impacts)
        assert bm.max_rotation[0, i, j] == pytest.approx(float(one.max_rotation))
    assert "restitution_factor = 0.8" in bm.select(0).motion
    given = jr.behavior_map(lam, size, base, pulse, restitution=0.7)
    one = jr.simulate(jr.Block(lam[2], size[1], restitution=0.7), base, pulse)
    assert given.impacts[2, 1] == int(one.impacts)
    with pytest.raises(ValueError, match="restitution_factor"):
        jr.behavior_map(lam, size, base, pulse, restitution_factor=[1.0, 1.3])
    with pytest.raises(ValueError, match="restitution_factor"):
        jr.behavior_map(lam, size, base, pulse, restitution_factor=[[1.0]])


def test_cells_with_f_e0_above_one_are_invalid_input():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    base = jr.LinearIsolator(2.0, 0.35, jnp.array([0.1, 0.5]))
    # lambda = 3: e0 = 0.840 (mass ratio 0.1) and 0.806 (0.5): f = 1.3 breaks both.
    bm = jr.behavior_map(
        [3.0], [0.5], base, pulse, restitution_factor=[1.0, 1.3], progress=False
    )
    status = np.asarray(bm.status)[:, :, 0, 0]  # (bases, factors)
    assert (status[:, 0] != jr.Status.INVALID_INPUT).all()
    assert (status[:, 1] == jr.Status.INVALID_INPUT).all()
    assert np.isnan(np.asarray(bm.max_rotation)[:, 1]).all()
    # As `simulate` under `jit` reports the same cell:
    one = jax.jit(
        lambda f: jr.simulate(
            jr.Block(3.0, 0.5, restitution_factor=f),
            jr.LinearIsolator(2.0, 0.35, 0.1),
            pulse,
        )
    )(1.3)
    assert int(one.status) == jr.Status.INVALID_INPUT
