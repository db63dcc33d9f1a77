"""Fragility curves: the lognormal maximum-likelihood fit and the ensemble."""

import numpy as np
import pytest
from scipy.stats import norm

import jaxrock as jr


def test_lognormal_fit_recovers_known_parameters():
    rng = np.random.default_rng(0)
    im = np.geomspace(0.05, 5.0, 400)
    failed = rng.random(im.size) < norm.cdf(np.log(im / 0.8) / 0.4)
    median, beta = jr.fit_lognormal(im, failed)
    assert median == pytest.approx(0.8, rel=0.1)
    assert beta == pytest.approx(0.4, rel=0.25)

    # The maximum: no point of a fine grid has a higher likelihood.
    def loglik(m, b):
        z = np.log(im / m) / b
        return np.sum(np.where(failed, norm.logcdf(z), norm.logcdf(-z)))

    best = loglik(median, beta)
    for m in median * np.array([0.97, 1.03]):
        for b in beta * np.array([0.95, 1.0, 1.05]):
            assert loglik(m, b) <= best + 1e-6
    assert np.isnan(jr.fit_lognormal(im, np.zeros(im.size, bool))[0])


def test_fragility_of_a_block_under_scaled_pulse():
    p = jr.near_fault_pulse("San Fernando PCD/SN")
    scales = np.linspace(0.1, 2.0, 24)
    motions = jr.MPPulse(scales * p.amplitude, p.frequency, p.gamma, p.phase)
    states = ["uplift", "rotation:0.05", "rotation:1.0", "overturning"]
    frag = jr.fragility(
        4.0, 1.0, jr.FixedBase(), motions, measure="pga_ratio", damage_states=states
    )
    # pga_ratio = PGA / (g tan alpha): the block uplifts exactly where it exceeds 1.
    np.testing.assert_array_equal(frag.rocked, frag.im > 1.0)
    assert frag.median_rocking == pytest.approx(1.0, abs=0.1)
    assert frag.overturned.any() and not frag.overturned.all()
    assert frag.median_overturning > frag.median_rocking
    assert np.all(frag.status == jr.Status.SUCCESS)
    curve = frag.probability(np.array([0.5, 5.0]))
    assert curve[0] < 0.5 < curve[1]
    # Rocking is separated at pga_ratio 1: its fit is a step there (beta 0).
    below, above = frag.im[~frag.rocked].max(), frag.im[frag.rocked].min()
    assert frag.beta_rocking == 0.0
    assert frag.median_rocking == pytest.approx(np.sqrt(below * above), rel=1e-12)
    step = frag.probability([below, frag.median_rocking, above], "rocking")
    np.testing.assert_array_equal(step, [0.0, 0.5, 1.0])
    # No curve, smooth or a step, has a value at IM <= 0 or NaN.
    for im in (np.nan, -1.0, 0.0):
        for which in ("rocking", "overturning"):
            with pytest.raises(ValueError, match="`im` must be finite and > 0"):
                frag.probability(im, which)
    # Damage states: each its own fit, read off the results, nested.
    assert frag.damage_states == (
        "uplift",
        "rotation:0.05",
        "rotation:1",
        "overturning",
    )
    alpha = np.arctan(1 / 4.0)
    np.testing.assert_allclose(frag.max_rotation[frag.overturned], np.pi / 2 / alpha)
    reached = frag.exceeded
    np.testing.assert_array_equal(reached[:, 0], frag.rocked)
    np.testing.assert_array_equal(reached[:, 1], frag.max_rotation > 0.05)
    np.testing.assert_array_equal(reached[:, 2], frag.max_rotation > 1.0)
    np.testing.assert_array_equal(reached[:, 3], frag.overturned)
    assert np.all(reached[:, 1:] <= reached[:, :-1])  # each implies the one before
    # rocking without overturning, some of it beyond 0.05 alpha and some below
    assert (
        0
        < (reached[:, 1] & ~reached[:, 3]).sum()
        < (reached[:, 0] & ~reached[:, 3]).sum()
    )
    for k in range(4):
        fit = jr.fit_lognormal(frag.im, reached[:, k])
        assert (frag.median_damage[k], frag.beta_damage[k]) == fit
    assert (frag.median_damage[0], frag.beta_damage[0]) == (
        frag.median_rocking,
        frag.beta_rocking,
    )
    im = [0.8, 1.5, 3.0, 6.0]
    np.testing.assert_array_equal(
        frag.probability(im, "rotation:1.0"), frag.probability(im, "rotation:1")
    )
    np.testing.assert_array_equal(
        frag.probability(im, "overturning"), frag.probability(im, states[3])
    )
    with pytest.raises(ValueError, match="`which` must be 'rocking', 'overturning'"):
        frag.probability(im, "rotation:0.5")
    # As labeled arrays: the batch of pulses, by amplitude (m/s).
    pytest.importorskip("xarray")
    ds = frag.to_xarray()
    assert ds.im.dims == ("motion",) and ds.im.attrs["units"] == "1"
    np.testing.assert_array_equal(ds.amplitude, motions.amplitude)
    assert ds.amplitude.attrs["units"] == "m/s" and float(ds.gamma) == float(p.gamma)
    strong = float(motions.amplitude[20])
    assert bool(ds.overturned.sel(amplitude=strong)) == frag.overturned[20]
    np.testing.assert_array_equal(ds.rocked, frag.rocked)
    assert list(ds.damage_state.values) == list(frag.damage_states)
    assert ds.exceeded.dims == ("motion", "damage_state")
    np.testing.assert_array_equal(
        ds.exceeded.sel(damage_state="rotation:1"), frag.max_rotation > 1.0
    )
    np.testing.assert_array_equal(ds.median_damage, frag.median_damage)
    assert ds.median_damage.attrs["units"] == "1"
    assert ds.max_base_displacement.attrs["units"] == "m"


@pytest.fixture(scope="module")
def isolated():
    """A block on the linear isolator under a pulse at 10 amplitudes, with
    the isolator's displacement among the damage states."""
    p = jr.near_fault_pulse("San Fernando PCD/SN")
    scales = np.geomspace(0.2, 3.0, 10)
    motions = jr.MPPulse(scales * p.amplitude, p.frequency, p.gamma, p.phase)
    states = ["uplift", "overturning", "displacement:0.1", "displacement:0.3"]
    base = jr.LinearIsolator(2.0, 0.35, 0.5)
    return jr.fragility(3.0, 1.0, base, motions, damage_states=states, progress=False)


def test_damage_states_of_an_isolator(isolated):
    frag = isolated
    assert frag.damage_states[2:] == ("displacement:0.1", "displacement:0.3")
    u = frag.max_base_displacement
    np.testing.assert_array_equal(frag.exceeded[:, 2], u > 0.1)
    np.testing.assert_array_equal(frag.exceeded[:, 3], u > 0.3)
    # The grid reaches either capacity in some analyses and not in others.
    assert 0 < frag.exceeded[:, 3].sum() < frag.exceeded[:, 2].sum() < u.size
    # The base moves more under a stronger pulse (a linear isolator).
    assert np.all(np.diff(u[~frag.overturned]) > 0)
    for k in range(4):
        fit = jr.fit_lognormal(frag.im, frag.exceeded[:, k])
        np.testing.assert_array_equal((frag.median_damage[k], frag.beta_damage[k]), fit)
    assert frag.median_damage[2] < frag.median_damage[3]


def test_damage_states_are_plotted_together(isolated):
    from jaxrock import plot

    ax = plot.fragility(isolated, title="four states")
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    for state in isolated.damage_states:
        assert f"{state} (1) or not (0)" in labels
        assert any(label.startswith(f"P({state}): median") for label in labels)
    assert ax.get_xlabel() == "peak ground acceleration (m/s^2)"


@pytest.mark.parametrize(
    "base, states, message",
    [
        ("fixed", ["rotation"], "`damage_states` must be names of the form"),
        ("fixed", ["rotation:-1"], "`damage_states` must be names"),
        ("fixed", ["rotation:nan"], "`damage_states` must be names"),
        ("fixed", ["collapse"], "`damage_states` must be names"),
        ("fixed", [0.5], "`damage_states` must be names"),
        ("fixed", 3, "`damage_states` must be a sequence of names"),
        ("fixed", ["overturning", "uplift"], "must nest.*'uplift' after 'overturning'"),
        (
            "fixed",
            ["rotation:0.5", "rotation:0.2"],
            "'rotation:0.2' after 'rotation:0.5'",
        ),
        ("fixed", ["uplift", "uplift"], "must nest.*none twice"),
        ("fixed", ["rotation:7"], "beyond the block's reach.*6.41"),
        ("fixed", ["displacement:0.1"], "a FixedBase does not move"),
        ("linear", ["displacement:0.2", "displacement:0.1"], "must nest"),
    ],
)
def test_damage_states_are_checked_before_any_analysis(
    base, states, message, monkeypatch
):
    from jaxrock import _fragility

    def no_map(*args, **kwargs):
        raise AssertionError("the map ran before the damage states were checked")

    monkeypatch.setattr(_fragility, "behavior_map", no_map)
    base = jr.FixedBase() if base == "fixed" else jr.LinearIsolator(2.0, 0.35, 0.5)
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    with pytest.raises(ValueError, match=message):
        jr.fragility(4.0, 1.0, base, pulse, scales=[1.0, 2.0], damage_states=states)


@pytest.mark.parametrize(
    "im, failed, median",
    [
        # One motion scaled: every failure above every non-failure.
        (np.geomspace(0.1, 2.0, 40), np.geomspace(0.1, 2.0, 40) > 1.0, None),
        ([1.0, 2.0, 3.0, 10.0, 11.0, 12.0], [0, 0, 0, 1, 1, 1], np.sqrt(30.0)),
        # A tie at the boundary: the step is at the tied IM.
        ([1.0, 2.0, 2.0, 3.0], [0, 0, 1, 1], 2.0),
        ([2.0, 1.0], [1, 0], np.sqrt(2.0)),
    ],
)
def test_lognormal_fit_of_separated_outcomes_is_a_step(im, failed, median):
    im, failed = np.asarray(im), np.asarray(failed, bool)
    if median is None:
        median = np.sqrt(im[~failed].max() * im[failed].min())
    assert jr.fit_lognormal(im, failed) == (pytest.approx(median, rel=1e-12), 0.0)


@pytest.mark.parametrize(
    "im, failed",
    [
        ([1.0, 2.0, 3.0, 4.0], [1, 1, 0, 0]),  # every failure below
        ([1.0, 2.0, 3.0, 4.0, 5.0], [1, 0, 1, 0, 0]),
        ([2.0, 2.0, 2.0], [0, 1, 1]),  # one IM for all
    ],
)
def test_lognormal_fit_of_failures_not_leaning_to_larger_im_is_nan(im, failed):
    assert np.isnan(jr.fit_lognormal(im, failed)).all()


def _exact_fit(im, k, n):
    """The maximum-likelihood (median, beta) by SciPy, written apart from
    jaxrock's Newton: BFGS on (ln median, ln beta) with the analytic gradient,
    then the score equations solved by `root` (hybr, xtol 1e-15)."""
    from scipy.optimize import minimize, root
    from scipy.special import log_ndtr

    x = np.log(im)

    def score(p):  # the gradient of the negative log-likelihood in (mu, ln b)
        mu, b = p[0], np.exp(p[1])
        z = (x - mu) / b
        up = np.exp(norm.logpdf(z) - log_ndtr(z))  # phi / Phi
        down = np.exp(norm.logpdf(z) - log_ndtr(-z))
        dz = k * up - (n - k) * down  # d loglik / dz
        return -np.array([np.sum(dz * -1 / b), np.sum(dz * -z)])

    def nll(p):
        z = (x - p[0]) / np.exp(p[1])
        return -np.sum(k * log_ndtr(z) + (n - k) * log_ndtr(-z))

    start = np.array([x.mean(), np.log(x.std())])
    p = minimize(nll, start, jac=score, method="BFGS", options={"gtol": 1e-12}).x
    p = root(score, p, method="hybr", tol=1e-15).x
    assert np.abs(score(p)).max() < 1e-9
    return np.exp(p[0]), np.exp(p[1])


@pytest.mark.parametrize("seed", range(6))
def test_lognormal_fit_is_the_exact_maximum_likelihood(seed):
    rng = np.random.default_rng(seed)
    size = [12, 40, 200, 1000, 25, 300][seed]
    median, beta = np.exp(rng.normal(0.0, 1.0)), rng.uniform(0.15, 1.2)
    im = np.exp(rng.normal(np.log(median), 1.5 * beta, size))
    failed = rng.random(size) < norm.cdf(np.log(im / median) / beta)
    got = jr.fit_lognormal(im, failed)
    want = _exact_fit(im, failed.astype(float), np.ones(size))
    np.testing.assert_allclose(got, want, rtol=1e-8)
    # The binomial form of a multiple-stripe analysis: k of n at each level.
    levels = np.geomspace(0.2, 3.0, 8) * median
    n = rng.integers(1, 40, levels.size)
    k = rng.binomial(n, norm.cdf(np.log(levels / median) / beta))
    if 0 < k.sum() < n.sum() and (k[:-1] > 0).any():
        got = jr.fit_lognormal(levels, k, trials=n)
        if got[1] > 0:
            np.testing.assert_allclose(got, _exact_fit(levels, k, n), rtol=1e-8)
    # Binary outcomes are the binomial form with one trial a level.
    np.testing.assert_array_equal(
        jr.fit_lognormal(im, failed.astype(int), trials=1), jr.fit_lognormal(im, failed)
    )


def test_lognormal_fit_refuses_bad_counts():
    with pytest.raises(ValueError, match="`trials` must be whole numbers >= 1"):
        jr.fit_lognormal([1.0, 2.0], [0, 1], trials=0)
    with pytest.raises(ValueError, match="`failed` must count the failures"):
        jr.fit_lognormal([1.0, 2.0], [0, 3], trials=2)


def test_a_multiple_stripe_analysis_is_the_binomial_fit_of_its_stripes():
    """`levels`: every record scaled so that its own Sa(1 s) is each level
    (the analyses' measures are the levels), one map; the fit over the
    analyses is the binomial fit of the counts per level; a measure that
    does not grow with amplitude, pulses, and `scales` with `levels` are
    refused."""
    suite = jr.Record.stack(jr.records.fema_p695()[:10])
    levels = np.linspace(3.0, 9.0, 7)
    frag = jr.fragility(
        4.0, 1.0, jr.FixedBase(), suite, levels=levels, measure="sa:1.0"
    )
    np.testing.assert_allclose(
        frag.im.reshape(7, 10), np.repeat(levels[:, None], 10, axis=1), rtol=1e-12
    )
    lv, k, n = frag.stripes("overturning")
    assert np.all(np.diff(k) >= 0) and 0 < k[3] < n[3]  # not separated
    median, beta = jr.fit_lognormal(lv, k, trials=n)
    assert frag.median_overturning == pytest.approx(median, rel=1e-10)
    assert frag.beta_overturning == pytest.approx(beta, rel=1e-10)
    ds = frag.to_xarray()
    assert ds.im.dims == ("level", "record")
    assert frag.motion.startswith("suite of 10 records (dt = ")
    assert frag.motion.endswith(", scaled to 7 levels of sa:1.0")
    with pytest.raises(ValueError, match="d5_95"):
        jr.fragility(4.0, 1.0, jr.FixedBase(), suite, levels=levels, measure="d5_95")
    with pytest.raises(ValueError, match="Record"):
        pulse = jr.near_fault_pulse("Northridge JFA/SN")
        jr.fragility(4.0, 1.0, jr.FixedBase(), pulse, levels=levels)
    with pytest.raises(ValueError, match="not both"):
        jr.fragility(4.0, 1.0, jr.FixedBase(), suite, levels=levels, scales=[1.0])


@pytest.mark.parametrize("measure", ["tp", "d5_95", "frequency_ratio"])
def test_one_motion_scaled_against_a_measure_it_does_not_scale_is_refused(measure):
    """Such a measure is one number over the analyses: no fit (NaN) is
    possible, and the error says why before any analysis runs."""
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    with pytest.raises(ValueError, match=f"`measure` '{measure}' does not grow"):
        jr.fragility(
            4.0, 1.0, jr.FixedBase(), pulse, scales=[0.5, 1.0], measure=measure
        )


def test_a_bootstrap_band_over_records_holds_the_fit():
    """`confidence_band`: records drawn with replacement and refitted; the
    band holds the fitted curve where it is uncertain, widens with the
    level, is reproducible for a seed, and its interval of medians holds the
    fit's median."""
    suite = jr.Record.stack(jr.records.fema_p695()[:10])
    frag = jr.fragility(
        4.0,
        1.0,
        jr.FixedBase(),
        suite,
        levels=np.linspace(3.0, 9.0, 7),
        measure="sa:1.0",
    )
    band = frag.confidence_band(samples=200, level=0.9, seed=1)
    narrow = frag.confidence_band(samples=200, level=0.5, seed=1)
    assert band.fitted >= 190
    assert np.all(band.lower <= narrow.lower + 1e-12)
    assert np.all(narrow.upper <= band.upper + 1e-12)
    fitted = frag.probability(band.im)
    uncertain = (fitted > 0.05) & (fitted < 0.95)
    assert np.all(band.lower[uncertain] <= fitted[uncertain])
    assert np.all(fitted[uncertain] <= band.upper[uncertain])
    assert band.median[0] < frag.median_overturning < band.median[1]
    again = frag.confidence_band(samples=200, level=0.9, seed=1)
    np.testing.assert_array_equal(again.lower, band.lower)
    for samples in ("10", 2.5, True):
        with pytest.raises(ValueError, match="`samples` an integer >= 2"):
            frag.confidence_band(samples=samples)
    with pytest.raises(ValueError, match="level"):
        frag.confidence_band(level=1.5)


def test_a_suite_scaled_beforehand_is_bootstrapped_by_its_records():
    """A suite scaled before `fragility` (`Record.scaled`) is its records at
    each factor: the bootstrap draws a record's analyses together, as it
    does for the same suite given with `scales`, not each (factor, record)
    pair as a motion of its own (a band too narrow)."""
    suite = jr.Record.stack(jr.records.fema_p695()[:4])
    factors = np.array([0.5, 1.0, 2.0, 4.0])
    given = jr.fragility(4.0, 1.0, jr.FixedBase(), suite, scales=factors)
    before = jr.fragility(4.0, 1.0, jr.FixedBase(), suite.scaled(factors))
    np.testing.assert_array_equal(before.motion_index, np.tile(np.arange(4), 4))
    np.testing.assert_array_equal(before.motion_index, given.motion_index)
    assert before.motion_names == given.motion_names == suite.names()
    np.testing.assert_array_equal(before.overturned, given.overturned)
    np.testing.assert_allclose(before.im, given.im, rtol=1e-14)
    a = given.confidence_band("rocking", samples=50, seed=3)
    b = before.confidence_band("rocking", samples=50, seed=3)
    assert a.fitted == b.fitted >= 40 and a.median[0] < a.median[1]
    np.testing.assert_allclose(b.median, a.median, rtol=1e-9)
    np.testing.assert_allclose(b.upper, a.upper, atol=1e-9)


def test_a_stripe_s_ties_are_not_broken_by_rounding():
    """The measures of a stripe's records, each scaled to the level, are
    its level: 1 ulp of rounding in own * (level / own) must not order them.
    Two records at PGV 0.01 (neither rocks) and 0.2 (one rocks): the stripes
    are separated, a step at 0.2 as `fit_lognormal` of the counts gives, not
    a fit with beta > 0."""
    dt = 0.01
    t = dt * np.arange(300)
    window = np.sin(np.pi * t / t[-1])
    # 1.1256... makes record A's PGV at 0.2 come out 1 ulp below 0.2.
    fast = jr.Record(1.1256281407035176 * (np.sin(2 * np.pi * 5 * t) * window), dt)
    slow = jr.Record(np.sin(2 * np.pi * 0.5 * t) * window, dt)
    levels = np.array([0.01, 0.2])
    frag = jr.fragility(
        4.0,
        1.0,
        jr.FixedBase(),
        jr.Record.stack([fast, slow]),
        levels=levels,
        measure="pgv",
    )
    np.testing.assert_array_equal(frag.im, np.repeat(levels, 2))
    assert frag.rocked.tolist() == [False, False, True, False]
    lv, k, n = frag.stripes("rocking")
    assert (
        (frag.median_rocking, frag.beta_rocking)
        == jr.fit_lognormal(lv, k, trials=n)
        == (0.2, 0.0)
    )


def test_a_bootstrap_over_one_motion_is_refused():
    """One pulse at several scales is one motion: every resample draws it,
    and a band of no width is refused with the reason."""
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    frag = jr.fragility(
        4.0, 1.0, jr.FixedBase(), pulse, scales=np.geomspace(0.2, 2.0, 6)
    )
    assert frag.rocked.any() and not frag.rocked.all()
    with pytest.raises(ValueError, match="at least 2 motions"):
        frag.confidence_band("rocking")


@pytest.mark.parametrize(
    "base, refused",
    [
        (jr.LinearIsolator(2.0, 0.35, 0.5, capacity=0.1), True),
        # With a stop the base's motion past the capacity is modelled.
        (jr.LinearIsolator(2.0, 0.35, 0.5, capacity=0.1, stop=jr.Stop(0.05)), False),
        (jr.FrictionPendulum(0.11, 0.25, 0.5), True),  # the dish's radius R
        (jr.LinearIsolator(2.0, 0.35, 0.5), False),
    ],
)
def test_a_displacement_state_beyond_the_capacity_is_refused(
    base, refused, monkeypatch
):
    """Past its capacity (without a stop) or its geometric limit an analysis
    ends CAPACITY_EXCEEDED and its max |u| is the unbounded model's: a
    displacement state beyond it would be fitted on displacements the base
    cannot reach."""
    from jaxrock import _fragility

    class Ran(Exception):
        pass

    def no_map(*args, **kwargs):
        raise Ran

    monkeypatch.setattr(_fragility, "behavior_map", no_map)
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    states = ["displacement:0.1", "displacement:0.3"]
    if refused:
        with pytest.raises(ValueError, match="'displacement:0.3' is beyond the"):
            jr.fragility(4.0, 1.0, base, pulse, scales=[1.0, 2.0], damage_states=states)
    else:
        with pytest.raises(Ran):
            jr.fragility(4.0, 1.0, base, pulse, scales=[1.0, 2.0], damage_states=states)


def test_damage_state_names_write_their_thresholds_short():
    """A state's name writes its threshold as Python's shortest repr: a tiny
    threshold is not written out in 300 digits, and 1.0 is "1"."""
    from jaxrock._fragility import check_damage_states

    names, parsed = check_damage_states(
        ["rotation:1e-300", "rotation:0.50", "rotation:1.0", "overturning"],
        4.0,
        jr.LinearIsolator(2.0, 0.35, 0.5),
    )
    assert names == ("rotation:1e-300", "rotation:0.5", "rotation:1", "overturning")
    assert parsed[0] == ("rotation", 1e-300)


PULSE = jr.near_fault_pulse("San Fernando PCD/SN")


@pytest.mark.parametrize("scales", [[1.0], [0.5, 1.0, 1.5]])
@pytest.mark.parametrize("name", ["restitution_factor", "restitution"])
def test_fragility_refuses_several_restitution_values(scales, name):
    with pytest.raises(ValueError, match=f"`{name}` must be one number"):
        jr.fragility(
            4.0,
            1.0,
            jr.FixedBase(),
            PULSE,
            scales=scales,
            progress=False,
            **{name: [0.5, 0.9]},
        )


def test_overturning_spectrum_refuses_several_restitution_values():
    with pytest.raises(ValueError, match="`restitution_factor` must be one number"):
        jr.overturning_spectrum(
            jr.Block(6.0, 1.0),
            jr.FixedBase(),
            [3.0],
            [1.5],
            restitution_factor=[0.5, 0.9],
            progress=False,
        )


@pytest.mark.parametrize("scales", [[1.0, np.nan], [1.0, -0.5], [0.0]])
def test_fragility_names_scales(scales):
    with pytest.raises(ValueError, match="`scales`"):
        jr.fragility(
            3.0, 1.0, jr.FixedBase(), jr.near_fault_pulse("Tabas TAB/SP"), scales=scales
        )
