"""The closed-form ground motions' inputs: `near_fault_pulse`'s `scale`."""

import numpy as np
import pytest

import jaxrock as jr

NAME = "Northridge JFA/SN"


@pytest.mark.parametrize(
    "scale", ["2", True, None, [2.0], np.array([1.0, 2.0]), 0.0, -1.0, np.inf, np.nan]
)
def test_near_fault_pulse_refuses_a_scale_that_is_not_one_positive_number(scale):
    """Strings, booleans, None and arrays are refused, not converted; the
    message names `scale` and its range. (`Record.scaled` and the pulses'
    `scaled` read their factors the same way.)"""
    message = r"`scale` must be (finite and > 0|one number), got "
    with pytest.raises(ValueError, match=message):
        jr.near_fault_pulse(NAME, scale=scale)
    if not isinstance(scale, (list, np.ndarray)):
        with pytest.raises(ValueError, match="`factor` must be finite and > 0"):
            jr.near_fault_pulse(NAME).scaled(scale)


@pytest.mark.parametrize("scale", [2, 2.0, np.float32(2.0), np.array(2.0)])
def test_near_fault_pulse_scales_the_amplitude(scale):
    """Integers, NumPy scalars and 0-d arrays are one number."""
    pulse = jr.near_fault_pulse(NAME, scale=scale)
    assert float(pulse.amplitude) == pytest.approx(2 * 0.87, rel=1e-15)


def test_near_fault_pulse_names_a_scale_that_makes_the_amplitude_overflow():
    """A finite `scale` whose amplitude overflows is refused by its name, not
    as the pulse's `amplitude` the user never gave."""
    with pytest.raises(ValueError, match=r"`scale` times the pulse's amplitude"):
        jr.near_fault_pulse(NAME, scale=1e308)
