"""Displacement stops: `capacity=D, stop=Stop(period, damping)` on an
isolator, a spring and a dashpot that push the base back past |u| = D.

Against the independent SciPy reference (tests/reference.py, which adds the
stop's force to its own equations and ends its solves at |u| = D), at rtol
1e-10 / atol 1e-12 on both sides: the same outcome and impacts, max rotation
and max base displacement within 1e-6 relative, on the linear isolator and
the friction pendulum, with cases where the stop throws a rocking block over
and lifts one that stood still. Maps equal `simulate`.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference as ref
from test_reference import BASES, _pulse

import jaxrock as jr

TOL = dict(rtol=1e-10, atol=1e-12)


def _isolator(key, **limit):
    if key == "linear":
        return jr.LinearIsolator(2.0, 0.35, 0.5, **limit)
    return jr.FrictionPendulum(0.11, 2.24, 0.5, **limit)


# (base, pulse, slenderness, size, scale, capacity D, stop period, damping)
CASES = [
    ("linear", "San Fernando PCD/SN", 3.0, 0.5, 1.0, 0.15, 0.05, 0.2),  # thrown over
    ("linear", "Bucharest BRI/SN", 5.0, 2.0, 1.0, 0.1, 0.05, 0.3),
    ("linear", "Aigion AEG/Lon", 2.5, 0.8, 1.5, 0.05, 0.05, 0.2),  # lifted, 21 impacts
    ("fps", "San Fernando PCD/SN", 4.0, 1.0, 1.0, 0.25, 0.05, 0.2),  # thrown over
    ("fps", "Imperial Valley E05/SN", 4.0, 2.5, 1.5, 0.2, 0.08, 0.2),  # 45 impacts
]


def _both(case):
    key, name, lam, r, scale, capacity, period, damping = case
    motion, (acc, t_end, max_step) = _pulse(name, scale)
    base = _isolator(key, capacity=capacity, stop=jr.Stop(period, damping))
    ours = jr.simulate(jr.Block(lam, r), base, motion, duration=t_end + 5.0, **TOL)
    theirs = ref.simulate(
        lam,
        r,
        BASES[key][1],
        acc,
        t_end + 5.0,
        max_step,
        stop=(capacity, period, damping),
    )
    return ours, theirs


@pytest.mark.parametrize("case", CASES, ids=str)
def test_matches_reference(case):
    ours, theirs = _both(case)
    assert int(ours.status) == jr.Status.SUCCESS  # the stop is modelled
    assert int(ours.outcome) == theirs["outcome"]
    assert int(ours.impacts) == theirs["impacts"]
    assert float(ours.max_rotation) == pytest.approx(theirs["max_rotation"], rel=1e-6)
    assert float(ours.max_base_displacement) == pytest.approx(
        theirs["max_base_displacement"], rel=1e-6
    )
    capacity = case[5]
    assert capacity < float(ours.max_base_displacement) < 1.2 * capacity


def test_the_stop_changes_the_fate():
    """Without the stop (the reference's own isolator) the first case rocks
    and the third never uplifts; against the stop both change."""
    outcomes = []
    for case in (CASES[0], CASES[2]):
        key, name, lam, r, scale, *_ = case
        _, (acc, t_end, max_step) = _pulse(name, scale)
        free = ref.simulate(lam, r, BASES[key][1], acc, t_end + 5.0, max_step)
        _, stopped = _both(case)
        outcomes.append((free["outcome"], stopped["outcome"]))
    assert outcomes == [(1, 2), (0, 1)]


@pytest.mark.parametrize("key", ["linear", "fps"])
def test_map_equals_simulate(key):
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    base = _isolator(key, capacity=0.15, stop=jr.Stop(0.05, 0.2))
    lam, size = np.array([2.5, 5.0]), np.array([0.5, 3.0])
    bm = jr.behavior_map(lam, size, base, pulse, **TOL)
    assert bm.counts()["capacity_exceeded"] == 0
    for i, slenderness in enumerate(lam):
        for j, r in enumerate(size):
            one = jr.simulate(jr.Block(slenderness, r), base, pulse, **TOL)
            for k in ("outcome", "impacts", "status"):
                assert getattr(bm, k)[i, j] == int(getattr(one, k)), (i, j, k)
            assert bm.max_rotation[i, j] == pytest.approx(
                float(one.max_rotation), rel=1e-6
            )
            assert bm.max_base_displacement[i, j] == pytest.approx(
                float(one.max_base_displacement), rel=1e-6
            )


@pytest.mark.parametrize("period, rtol", [(1e-3, 1e-8), (1e-2, 1e-6), (0.05, 1e-7)])
def test_a_touch_in_a_step_that_another_event_ends_is_kept(period, rtol):
    """The base leaves its stop and meets it on the other side within one
    segment, in a step that the block's apex ends too (Diffrax fires the
    first condition in order): the segment is redone up to the touch, at any
    tolerance. Undamped stops, the block overturned: `simulate` equals the
    map and the reference (at rtol 1e-10) in impacts and max abs(u)."""
    name = "San Fernando PCD/SN"
    pulse, (acc, t_end, max_step) = _pulse(name, 1.0)
    stop = jr.Stop(period, 0.0)
    base = jr.LinearIsolator(2.0, 0.05, 0.5, capacity=0.05, stop=stop)
    tol = dict(rtol=rtol, atol=rtol * 1e-2)
    one = jr.simulate(jr.Block(5.0, 1.0), base, pulse, **tol)
    bm = jr.behavior_map([5.0], [1.0], base, pulse, **tol)
    theirs = ref.simulate(
        5.0,
        1.0,
        ("linear", 2.0, 0.05, 0.5),
        acc,
        t_end + 5.0,
        max_step,
        stop=(0.05, period, 0.0),
    )
    assert int(one.outcome) == theirs["outcome"] == jr.Outcome.OVERTURNED
    assert int(one.impacts) == int(bm.impacts[0, 0]) == theirs["impacts"]
    assert int(one.segments) == int(bm.segments[0, 0])
    assert float(one.max_base_displacement) == pytest.approx(
        theirs["max_base_displacement"], rel=1e-5
    )


def test_a_redo_ends_half_way_for_a_condition_that_began_on_its_boundary():
    """`redo_limit` over a segment from t0 = 1 to an event at t = 3: a
    condition > 0 at t0 and < 0 at t crossed first, at its secant root; one
    that began on its boundary (<= 0 at t0: an event of its own began the
    segment) and is < 0 at t rose and crossed again unseen: the redo ends
    half-way; one > 0 at t, or not a candidate, asks for none."""
    from jaxrock._model import REDO_MARGIN, redo_limit

    t0, t = jnp.asarray(1.0), jnp.asarray(3.0)

    def limit(candidate, v0, v1):
        out = redo_limit(t0, t, [jnp.asarray(candidate)], [v0], [v1])
        return float(out)

    assert limit(True, 1.0, -1.0) == 0.5 * (2.0 + 3.0)  # root at 2 s
    assert limit(True, -7e-18, -0.5) == 2.0
    assert limit(True, 0.0, -0.5) == 2.0
    assert limit(True, -7e-18, 0.5) == float("inf")
    assert limit(False, 1.0, -1.0) == float("inf")
    assert limit(True, 1e-300, -1.0) <= 3.0 - REDO_MARGIN


def test_history_names_the_stop_and_gradients_go_through():
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    base = _isolator("linear", capacity=0.2, stop=jr.Stop(0.1, 0.1))
    r = jr.simulate(jr.Block(4.0, 1.0), base, pulse, history=True)
    assert "stop" in r.history.event_kinds
    assert np.max(np.abs(r.history.u)) > 0.2

    def displacement(period):
        limited = _isolator("linear", capacity=0.2, stop=jr.Stop(period, 0.1))
        return jr.simulate(jr.Block(6.0, 3.0), limited, pulse).max_base_displacement

    slope = jax.jacfwd(displacement)(0.1)
    h = 1e-6
    central = (displacement(0.1 + h) - displacement(0.1 - h)) / (2 * h)
    assert float(slope) == pytest.approx(float(central), rel=1e-4)
    assert float(slope) > 0  # a softer stop lets the base further in


def test_a_damped_stop_s_push_ends_at_an_event_past_the_gap():
    """A damped stop does not pull: its push w^2 d + 2 zeta w d' ends while
    the base is still past the gap (d > 0), a kink of its force. A step ends
    there (a `stop` event), where the push is 0 to the event's rounding, so
    values and derivatives converge across it at the solver's order."""
    capacity, period, zeta = 0.2, 0.1, 0.3
    base = _isolator("linear", capacity=capacity, stop=jr.Stop(period, zeta))
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    h = jr.simulate(jr.Block(4.0, 1.0), base, pulse, history=True).history
    w = 2 * np.pi / period
    ends = 0
    for t in np.array(h.event_times)[np.array(h.event_kinds) == "stop"]:
        i = np.flatnonzero(np.asarray(h.t) == t)[0]
        u, u_dot = h.u[i], h.u_dot[i]
        d = abs(u) - capacity
        if d > 1e-6 * capacity:  # not at the gap: the push's end
            push = w * w * d + 2 * zeta * w * np.sign(u) * u_dot
            assert abs(push) / w**2 < 1e-8 * capacity
            ends += 1
    assert ends >= 1


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: jr.Stop(0.0), "`Stop.period` must be"),
        (lambda: jr.Stop(0.05, 1.0), "`Stop.damping` must be"),
        (lambda: _isolator("linear", stop=jr.Stop(0.05)), "`stop` needs a `capacity`"),
        (lambda: jr.FixedBase(capacity=0.1, stop=jr.Stop(0.05)), "does not move"),
        (lambda: _isolator("linear", capacity=0.1, stop=0.05), "`stop` must be a Stop"),
    ],
)
def test_bad_stops_are_refused(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_a_block_at_rest_uplifts_where_the_base_meets_the_stop():
    """Where the base meets the stop its dashpot's force jumps (2 zeta w |u'|
    per unit mass): here past the block's uplift level, so the block
    uplifts at the touch, in `simulate`, the map and the reference."""
    pulse = (
        3.1370880259794047,
        1.2131967573043474,
        1.6975639464281524,
        350.15689702790473,
    )
    isolator = (3.0873068453719448, 0.0689662967902293, 0.934028793035921)
    block = (2.618564963313408, 0.4594458571596171)
    stop = (0.04652407964355269, 0.19069387403015475, 0.10660489629582091)
    acc, t_end, max_step = ref.mp_pulse(*pulse)
    base = jr.LinearIsolator(*isolator, capacity=stop[0], stop=jr.Stop(*stop[1:]))
    motion, window = jr.MPPulse(*pulse), dict(duration=t_end + 5.0, **TOL)
    one = jr.simulate(jr.Block(*block), base, motion, history=True, **window)
    bm = jr.behavior_map([block[0]], [block[1]], base, motion, **window)
    theirs = ref.simulate(
        *block, ("linear", *isolator), acc, t_end + 5.0, max_step, stop=stop
    )
    touch = one.history.event_times[one.history.event_kinds.index("stop")]
    assert float(one.uplift_time) == pytest.approx(touch, abs=1e-9)
    for uplift in (bm.uplift_time[0, 0], theirs["uplift_time"]):
        assert uplift == pytest.approx(touch, abs=1e-7)
    assert int(one.impacts) == bm.impacts[0, 0] == theirs["impacts"]
    assert int(one.outcome) == bm.outcome[0, 0] == theirs["outcome"]


def test_the_end_of_an_analysis_against_a_stiff_stop_is_located():
    """A block at rest on a base whose energy falls until its bound of |u|
    leaves the stop (period 0.047 s): only then is there a bound of its
    force, and the analysis ends ("quiet"). Its condition is continuous
    there, so the map locates its root as `simulate` does, instead of
    retrying one step until `max_steps`."""
    pulse = (3.2807587074275073, 2.2113948863226462, 2.695986804230815, 164.2899)
    isolator = (2.8634364653837627, 0.07219576867914736, 0.43107539002534856)
    block = (2.0737352696121247, 1.791602958462367)
    stop = jr.Stop(0.04708662278074155, 0.26668489900240355)
    base = jr.LinearIsolator(*isolator, capacity=0.08255998607265076, stop=stop)
    motion = jr.MPPulse(*pulse)
    one = jr.simulate(jr.Block(*block), base, motion, duration=3.0, history=True)
    bm = jr.behavior_map([block[0]], [block[1]], base, motion, duration=3.0)
    assert one.history.event_kinds[-1] == "quiet"
    assert int(one.status) == bm.status[0, 0] == jr.Status.SUCCESS
    assert int(one.impacts) == bm.impacts[0, 0]
    assert float(one.max_base_displacement) == pytest.approx(
        bm.max_base_displacement[0, 0], rel=1e-6
    )


def test_a_base_that_leaves_its_stop_and_meets_it_again_at_once():
    """A stiff stop (period 0.03 s) that the base leaves and meets again 3.7
    ms later, within the map's next step: each touch is located just past
    it, so the next segment's condition starts off its boundary and sees the
    return. The map, `simulate` and the reference agree at the default
    tolerance."""
    pulse = (6.6739147394146805, 1.2859609214720535, 2.8924946910382636, 221.8288)
    isolator = (1.5560126412543824, 0.24299677027396321, 0.40093296924805694)
    block = (2.807456668883611, 2.0813510184727457)
    stop = (0.10563480767956601, 0.0302873171699614, 0.19782145706583004)
    acc, t_end, max_step = ref.mp_pulse(*pulse)
    base = jr.LinearIsolator(*isolator, capacity=stop[0], stop=jr.Stop(*stop[1:]))
    motion, duration = jr.MPPulse(*pulse), t_end + 5.0
    one = jr.simulate(jr.Block(*block), base, motion, duration=duration)
    bm = jr.behavior_map([block[0]], [block[1]], base, motion, duration=duration)
    theirs = ref.simulate(
        *block, ("linear", *isolator), acc, duration, max_step, stop=stop
    )
    assert int(one.impacts) == bm.impacts[0, 0] == theirs["impacts"]
    for mine in (float(one.max_base_displacement), bm.max_base_displacement[0, 0]):
        assert mine == pytest.approx(theirs["max_base_displacement"], rel=1e-6)


def test_rocking_that_starts_where_the_base_meets_the_stop():
    """A frictionless pendulum that meets its stop (period 0.05 s) lifts the
    block there and it rocks; the reference, which applies the dashpot's
    force from the touch on, counts the same impacts (no impact at rest
    right after the touch) and the same maxima."""
    pulse = (
        1.584516367059516,
        0.8427334660167034,
        2.4356332099130604,
        338.3272762013994,
    )
    block = (2.181006979557361, 2.0130126539226314)
    stop = (0.046827284787625094, 0.04911830832106202, 0.259017067733425)
    isolator = (0.0, 2.7650916783036825, 0.6745152891938346)
    acc, t_end, max_step = ref.mp_pulse(*pulse)
    base = jr.FrictionPendulum(*isolator, capacity=stop[0], stop=jr.Stop(*stop[1:]))
    one = jr.simulate(
        jr.Block(*block), base, jr.MPPulse(*pulse), duration=t_end + 3.0, **TOL
    )
    theirs = ref.simulate(
        *block,
        ("fps", *isolator, 5e-4, 1.0, 0.9, 0.1, 2.0),
        acc,
        t_end + 3.0,
        max_step,
        stop=stop,
    )
    assert int(one.impacts) == theirs["impacts"]
    assert float(one.max_rotation) == pytest.approx(theirs["max_rotation"], rel=1e-6)
    assert float(one.max_base_displacement) == pytest.approx(
        theirs["max_base_displacement"], rel=1e-6
    )


def test_a_touch_passed_within_one_step_off_the_stop_is_seen():
    """A segment that starts off the stop (an impact 0.19 mm short of the
    gap, the base then moving out) has no stop force along it: a step may
    pass a whole touch (1.4 ms in and out of a damped stiff stop) and end
    off it again, its condition > 0 at both ends. Such a step ends moving
    inward with |u| within |u'| H of the gap, where `stop_passage` is <= 0:
    the touch is located. `simulate` equals the map and the reference."""
    iso = (1.3231152870499936, 0.2940538410692386, 0.4070934247393577)
    block = (4.33071392188063, 0.9946467161706369)
    pulse = (5.113898735405706, 1.5608435499497346, 3.433838383542118, 2.63293)
    stop = (0.03724876966711781, 0.01850348836860471, 0.7754002675049301)
    acc, t_end, max_step = ref.mp_pulse(*pulse)
    base = jr.LinearIsolator(*iso, capacity=stop[0], stop=jr.Stop(*stop[1:]))
    motion, window = jr.MPPulse(*pulse), dict(duration=t_end + 3.0, **TOL)
    one = jr.simulate(jr.Block(*block), base, motion, **window)
    bm = jr.behavior_map([block[0]], [block[1]], base, motion, **window)
    theirs = ref.simulate(
        *block, ("linear", *iso), acc, t_end + 3.0, max_step, stop=stop
    )
    assert int(one.impacts) == bm.impacts[0, 0] == theirs["impacts"]
    assert int(one.segments) == bm.segments[0, 0]
    for mine in (float(one.max_base_displacement), bm.max_base_displacement[0, 0]):
        assert mine == pytest.approx(theirs["max_base_displacement"], rel=1e-8)


def test_an_uplift_at_a_stop_contact_is_an_event_of_the_history():
    """A damped stop pushes the base the moment it meets it, which can lift
    the block at once: the history lists the uplift (at `uplift_time`) after
    the stop event, as every uplift."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 6.0, 0.01)
    ground = 3.0 * np.sin(2 * np.pi * 0.9 * t) * np.exp(-(((t - 2.0) / 1.2) ** 2))
    record = jr.Record(ground + 0.2 * rng.standard_normal(t.size), 0.01)
    base = jr.LinearIsolator(2.0, 0.1, 0.5, capacity=0.05, stop=jr.Stop(0.1, 0.2))
    r = jr.simulate(jr.Block(3.0, 0.5), base, record, history=True)
    h = r.history
    uplifts = h.event_times[np.array(h.event_kinds) == "uplift"]
    assert uplifts.size >= 1
    assert uplifts[0] == float(r.uplift_time)
    first = list(h.event_times).index(uplifts[0])
    assert h.event_kinds[first] == "stop"  # the same transition
