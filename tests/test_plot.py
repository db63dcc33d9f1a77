"""Plots: what they draw where, and the maps they refuse."""

import matplotlib.pyplot as plt
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import plot


@pytest.fixture(scope="module")
def pulse_batch_map():
    """A map under a batch of two pulses: leading axis "motion"."""
    pulses = jr.MPPulse(np.array([1.0, 2.0]), 0.68, 1.6, 180.0)
    return jr.behavior_map([3.0, 5.0], [0.5, 1.0], jr.FixedBase(), pulses)


def test_behavior_map_of_a_batch_says_to_select_a_member(pulse_batch_map):
    bm = pulse_batch_map
    assert bm.outcome.shape == (2, 2, 2)
    pattern = r"`bmap` must be one map, got a batch of shape \(2,\) \(axes: motion\)"
    with pytest.raises(ValueError, match=pattern + r".*bm\.select\(i\)"):
        plot.behavior_map(bm)
    with pytest.raises(ValueError, match=r"`maps\[1\]` must be one map"):
        plot.compare_maps([bm.select(0), bm])
    # What the message says to do draws.
    ax = plot.behavior_map(bm.select(1))
    assert sum(len(c.get_offsets()) for c in ax.collections) == 4  # a dot per cell
    fig = plot.compare_maps([bm.select(i) for i in range(2)])
    assert len([a for a in fig.axes if a.get_visible()]) == 2
    plt.close("all")


def test_response_marks_events_on_the_curve():
    """The overturn marker sits where theta/alpha ends, not at 0; uplifts and
    impacts at theta = 0."""
    r = jr.simulate(
        jr.Block(6.0, 0.5),
        jr.FixedBase(),
        jr.near_fault_pulse("Northridge JFA/SN"),
        history=True,
    )
    assert int(r.outcome) == jr.Outcome.OVERTURNED
    h = r.history
    fig = plot.response(r)
    lines = {line.get_label(): line for line in fig.axes[2].get_lines()}
    end = h.theta[-1] / h.alpha
    assert abs(end) > 9.0  # pi / (2 alpha): the block has fallen
    overturn = lines["overturn"]
    assert overturn.get_xdata()[0] == h.event_times[-1]
    assert overturn.get_ydata()[0] == pytest.approx(end, rel=1e-12)
    for kind in ("uplift", "impact"):
        np.testing.assert_allclose(lines[kind].get_ydata(), 0.0, atol=1e-9)
    plt.close(fig)
