"""jaxrock: rigid blocks rocking on seismically isolated bases, in JAX.

Importing jaxrock enables JAX's float64 mode (`jax_enable_x64`): every result
is float64 unless you turn it off again.
"""

import importlib.metadata

import jax

jax.config.update("jax_enable_x64", True)

from ._block import Block as Block  # noqa: E402
from ._ground import (  # noqa: E402
    NEAR_FAULT_PULSES as NEAR_FAULT_PULSES,
    AbstractGroundMotion as AbstractGroundMotion,
    MPPulse as MPPulse,
    Record as Record,
    near_fault_pulse as near_fault_pulse,
)
from ._isolators import (  # noqa: E402
    AbstractIsolator as AbstractIsolator,
    FixedBase as FixedBase,
    FrictionPendulum as FrictionPendulum,
    LinearIsolator as LinearIsolator,
)
from ._maps import BehaviorMap as BehaviorMap, behavior_map as behavior_map  # noqa: E402
from ._simulate import (  # noqa: E402
    EventKind as EventKind,
    History as History,
    Outcome as Outcome,
    Response as Response,
    SolverOptions as SolverOptions,
    Status as Status,
    simulate as simulate,
)
from . import design as design  # noqa: E402
from . import io as io  # noqa: E402

__version__ = importlib.metadata.version("jaxrock")
