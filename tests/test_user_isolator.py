"""The isolator of docs/isolators.md, written outside jaxrock: its example
runs as printed, and the class goes through simulate, maps and jacfwd."""

import re
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxrock as jr

PAGE = Path(__file__).resolve().parents[1] / "docs" / "isolators.md"
PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


@pytest.fixture(scope="module")
def page():
    """The page's code blocks, run in order in one namespace."""
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)
    assert len(blocks) == 2
    namespace = {}
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), namespace)
    return namespace


def test_a_spring_that_never_hardens_is_the_linear_isolator(page):
    soft = page["HardeningIsolator"](2.0, 0.35, 1e6, 0.5)
    for lam, r in [(3.0, 0.5), (4.0, 1.0)]:
        ours = jr.simulate(jr.Block(lam, r), soft, PULSE)
        linear = jr.simulate(jr.Block(lam, r), jr.LinearIsolator(2.0, 0.35, 0.5), PULSE)
        assert int(ours.outcome) == int(linear.outcome)
        assert int(ours.impacts) == int(linear.impacts)
        np.testing.assert_allclose(ours.max_rotation, linear.max_rotation, rtol=1e-9)


def test_a_batch_of_the_users_isolators_is_one_map(page):
    bases = page["HardeningIsolator"](2.0, 0.35, np.array([0.1, 0.3, 1e6]), 0.5)
    bm = jr.behavior_map([2.0, 2.5, 4.0], [0.4, 2.0], bases, PULSE, progress=False)
    assert bm.outcome.shape == (3, 3, 2)
    np.testing.assert_array_equal(bm.select(1).outcome, page["bm"].outcome)
    assert bm.coordinates.coords["hardening"][0] == ("base",)
    # A stiffer spring moves the base less.
    assert np.all(bm.max_base_displacement[0] <= bm.max_base_displacement[2])


def test_its_derivative_matches_central_differences(page):
    f, h = page["max_rotation"], 1e-5 * 0.3
    lo, hi = float(f(0.3 - h)), float(f(0.3 + h))
    derivative = float(jax.jacfwd(f)(0.3))
    assert abs(hi - lo) > 0
    assert derivative == pytest.approx((hi - lo) / (2 * h), rel=1e-4)


def test_out_of_range_and_missing_methods_are_named(page):
    with pytest.raises(ValueError, match="`hardening` must be finite and > 0"):
        page["HardeningIsolator"](2.0, 0.35, 0.0, 0.5)

    class NoForce(jr.AbstractIsolator):
        n_states = 2

        def initial_state(self):
            return np.zeros(2)

        def rates(self, state, u_ddot):
            return state

        block_mass_fraction = 0.5

        def free_vibration_bounds(self, state):
            return np.inf, np.inf

    with pytest.raises(TypeError, match="force"):
        NoForce()


class Spring(jr.AbstractIsolator):
    """A linear spring without damping, F / M = omega^2 u, omega = 2 pi / T:
    the least an isolator needs, written here alone."""

    period: jax.Array = jr.parameter("period", "s")
    mass_ratio: jax.Array = jr.parameter("mass_ratio", "1")
    n_states = 2  # (u, u')

    def initial_state(self):
        return jax.numpy.zeros(2, dtype=self.period.dtype)

    def force(self, state):
        return (2.0 * np.pi / self.period) ** 2 * state[0]

    def rates(self, state, u_ddot):
        return jax.numpy.stack([state[1], u_ddot])

    @property
    def block_mass_fraction(self):
        return self.mass_ratio / (1.0 + self.mass_ratio)

    def free_vibration_bounds(self, state):
        return np.inf, np.inf


def test_a_toy_spring_written_in_a_test_runs_through_simulate_maps_and_jacfwd():
    lam, size = np.array([2.5, 4.0, 6.0]), np.array([0.4, 1.5])
    spring = Spring(2.0, 0.5)
    linear = jr.LinearIsolator(2.0, 0.0, 0.5)  # the same physics, built in
    pulse = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.5)
    bm = jr.behavior_map(lam, size, spring, pulse, progress=False)
    assert len(np.unique(bm.outcome)) >= 2  # the comparison means something
    for i, slenderness in enumerate(lam):
        for j, r in enumerate(size):
            ours = jr.simulate(jr.Block(slenderness, r), spring, pulse)
            theirs = jr.simulate(jr.Block(slenderness, r), linear, pulse)
            assert int(bm.outcome[i, j]) == int(ours.outcome) == int(theirs.outcome)
            np.testing.assert_allclose(
                [bm.max_rotation[i, j], ours.max_rotation],
                float(theirs.max_rotation),
                rtol=1e-7,
            )

    def peak_u(period):
        base = Spring(period, 0.5)
        opts = dict(rtol=1e-12, atol=1e-14)
        return jr.simulate(
            jr.Block(2.5, 0.4), base, PULSE, **opts
        ).max_base_displacement

    h = 1e-5
    derivative = float(jax.jacfwd(peak_u)(2.0))
    central = (float(peak_u(2.0 + h)) - float(peak_u(2.0 - h))) / (2 * h)
    assert central != 0
    assert derivative == pytest.approx(central, rel=1e-5)


@pytest.mark.parametrize(
    "member, wrong, message",
    [
        ("rates", lambda self, s, a: jax.numpy.stack([s[1]]), r"rates.*got \(1,\)"),
        ("rates", lambda self, s, a: jax.numpy.stack([s[1], a, a]), r"got \(3,\)"),
        ("force", lambda self, s: (2.0 * np.pi / self.period) ** 2 * s, "scalar"),
        ("initial_state", lambda self: jax.numpy.zeros(3), r"state\(\).*\(3,\)"),
        ("initial_state", lambda self: None, "got None"),
        ("initial_state", lambda self: jax.numpy.zeros(2, "float32"), "float32"),
        ("n_states", 3, r"`n_states` = 3"),
    ],
)
def test_a_member_of_the_wrong_shape_is_named_before_anything_runs(
    member, wrong, message
):
    """A user isolator whose members disagree with `n_states` is refused by
    name, in simulate, maps and under jacfwd, rather than broadcast (rates of
    one entry ran to UNDECIDED with a rotation of 0) or failing deep inside."""
    buggy = type("Buggy", (Spring,), {member: wrong})
    pulse = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.5)
    with pytest.raises(ValueError, match=message):
        jr.simulate(jr.Block(2.5, 0.4), buggy(2.0, 0.5), pulse)
    with pytest.raises(ValueError, match=message):
        jr.behavior_map([2.5], [0.4], buggy(np.array([2.0, 2.5]), 0.5), pulse)
    with pytest.raises(ValueError, match=message):
        jax.jacfwd(
            lambda p: jr.simulate(jr.Block(2.5, 0.4), buggy(p, 0.5), pulse).max_rotation
        )(2.0)


def test_a_parameter_named_as_a_field_of_the_map_keeps_the_maps_labels():
    """A user's parameter named `size` (a bearing's) or `outcome` is the
    coordinate `base_size` / `base_outcome`: it replaced the blocks' sizes
    (the map's own `size` labels lost) or made `to_xarray` raise."""
    pytest.importorskip("xarray")
    for name in ("size", "outcome"):
        own = {"__annotations__": {name: jax.Array}, name: jr.parameter(name, "m")}
        bearing = type("Bearing", (Spring,), own)(2.0, 0.5, np.array([0.2, 0.4]))
        bm = jr.behavior_map([2.5], [0.4, 1.5], bearing, PULSE, progress=False)
        ds = bm.to_xarray()
        np.testing.assert_array_equal(ds["size"], [0.4, 1.5])
        assert ds["size"].dims == ("size",) and ds.outcome.dims[0] == "base"
        np.testing.assert_array_equal(ds["base_" + name], [0.2, 0.4])
        assert ds["base_" + name].attrs["units"] == "m"


def test_an_edited_isolator_of_the_same_name_is_another_map_in_a_store(tmp_path):
    """A store's key holds the code of a user's isolator class: the class
    edited (a stiffer spring) and run again into the store is refused, not
    read from the first class's chunks; the same class resumes."""
    pulse = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.5)
    stiffer = type(
        "Spring",
        (Spring,),
        {"force": lambda self, state: 2 * Spring.force(self, state)},
    )
    lam, size = [2.5], [0.4]
    first = jr.behavior_map(lam, size, Spring(2.0, 0.5), pulse, store=tmp_path)
    again = jr.behavior_map(lam, size, Spring(2.0, 0.5), pulse, store=tmp_path)
    np.testing.assert_array_equal(again.max_rotation, first.max_rotation)
    with pytest.raises(ValueError, match="another map"):
        jr.behavior_map(lam, size, stiffer(2.0, 0.5), pulse, store=tmp_path)


def test_a_block_mass_fraction_out_of_range_is_named():
    """m / M of a user's isolator outside (0, 1) is refused by its name,
    not as a coefficient of restitution it makes out of range."""
    heavy = type("Heavy", (Spring,), {"block_mass_fraction": property(lambda s: 2.0)})
    pulse = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.5)
    for run in (jr.simulate, lambda b, base, p: jr.behavior_map([2.5], [0.4], base, p)):
        with pytest.raises(ValueError, match=r"`Heavy.block_mass_fraction` must be in"):
            run(jr.Block(2.5, 0.4), heavy(2.0, 0.5), pulse)


def test_an_isolator_whose_force_is_nan_fails_as_a_solver_failure():
    """A force that turns NaN once the base moves fails the solve: the step
    size shrinks to nothing, and the analysis ends SOLVER_FAILED (not
    MAX_STEPS, which a larger limit would cure), in simulate and maps."""
    broken = type(
        "Broken",
        (Spring,),
        {
            "force": lambda self, s: jax.numpy.where(
                jax.numpy.abs(s[0]) > 1e-3, jax.numpy.nan, Spring.force(self, s)
            )
        },
    )
    pulse = jr.near_fault_pulse("San Fernando PCD/SN", scale=0.5)
    r = jr.simulate(jr.Block(2.5, 0.4), broken(2.0, 0.5), pulse)
    assert r.status == jr.Status.SOLVER_FAILED
    bm = jr.behavior_map([2.5, 4.0], [0.4], broken(2.0, 0.5), pulse)
    assert np.all(bm.status == jr.Status.SOLVER_FAILED)
