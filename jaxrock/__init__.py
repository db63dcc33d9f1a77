"""jaxrock: rigid blocks rocking on seismically isolated bases, in JAX.

Importing jaxrock changes four settings of the process (the documentation's
configuration page says what each does and how to opt out):

- JAX's float64 mode (`jax_enable_x64`) is turned on. jaxrock's tolerances
  are float64 tolerances: there is no float32 mode, and turning x64 off
  after the import is not supported.
- JAX's persistent compilation cache is pointed at `~/.cache/jaxrock/xla`
  (`$XDG_CACHE_HOME/jaxrock/xla`), with compiled programs kept whole in its
  `programs/` folder, and entries there that were cut short are deleted;
  `JAXROCK_CACHE=FOLDER` moves it, `JAXROCK_CACHE=off` turns it off, and a
  cache configured for JAX already is left as it is.
- `--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=
  1000000000000000` is added to `XLA_FLAGS`, so that XLA compiles each while
  loop on the CPU as one kernel, unless `XLA_FLAGS` sets XLA's backend
  options already, JAX has computed before the import (a warning says so),
  or `JAXROCK_LOOP_KERNELS=off`; `JAXROCK_LOOP_KERNELS=flattened` adds
  `xla_cpu_flatten_after_fusion`.
- `--xla_gpu_enable_command_buffer=+WHILE,+CONDITIONAL` is added to
  `XLA_FLAGS`, so that on a GPU loops and conditionals run on the device as
  CUDA graphs, unless `XLA_FLAGS` sets XLA's command buffers already or JAX
  has computed before the import.
"""

import importlib.metadata as _metadata

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._xla import compile_loops_whole, control_flow_as_gpu_graphs  # noqa: E402

compile_loops_whole()
control_flow_as_gpu_graphs()

from ._cache import enable_compilation_cache  # noqa: E402

enable_compilation_cache()

from . import design as design  # noqa: E402
from . import io as io  # noqa: E402
from . import records as records  # noqa: E402
from ._block import Block as Block  # noqa: E402
from ._design_spectrum import asce7_spectrum as asce7_spectrum  # noqa: E402
from ._design_spectrum import eurocode8_spectrum as eurocode8_spectrum
from ._fit import PulseFit as PulseFit  # noqa: E402
from ._fit import fit_pulse as fit_pulse
from ._fit import score_pulse as score_pulse
from ._floor import floor_motion as floor_motion  # noqa: E402
from ._fragility import Fragility as Fragility  # noqa: E402
from ._fragility import fit_lognormal as fit_lognormal
from ._fragility import fragility as fragility
from ._ground import (  # noqa: E402
    NEAR_FAULT_PULSES as NEAR_FAULT_PULSES,
)
from ._ground import (
    AbstractGroundMotion as AbstractGroundMotion,
)
from ._ground import (
    MPPulse as MPPulse,
)
from ._ground import (
    SinePulse as SinePulse,
)
from ._ground import (
    near_fault_pulse as near_fault_pulse,
)
from ._intensity import intensity_measure as intensity_measure  # noqa: E402
from ._isolators import (
    AbstractBoucWenIsolator as AbstractBoucWenIsolator,
)
from ._isolators import (
    AbstractClosedFormBoucWen as AbstractClosedFormBoucWen,
)
from ._isolators import (
    AbstractFrictionPendulum as AbstractFrictionPendulum,
)
from ._isolators import (  # noqa: E402
    AbstractIsolator as AbstractIsolator,
)
from ._isolators import (
    BilinearIsolator as BilinearIsolator,
)
from ._isolators import (
    ConicalRollingIsolator as ConicalRollingIsolator,
)
from ._isolators import (
    FixedBase as FixedBase,
)
from ._isolators import (
    FrictionPendulum as FrictionPendulum,
)
from ._isolators import (
    IntegratedFrictionPendulum as IntegratedFrictionPendulum,
)
from ._isolators import (
    LinearIsolator as LinearIsolator,
)
from ._isolators import (
    SphericalRollingIsolator as SphericalRollingIsolator,
)
from ._isolators import Stop as Stop
from ._labeled import Coordinates as Coordinates  # noqa: E402
from ._maps import BehaviorMap as BehaviorMap  # noqa: E402
from ._maps import behavior_map as behavior_map
from ._misc import Constraint as Constraint  # noqa: E402
from ._misc import parameter as parameter
from ._record import (
    Record as Record,
)
from ._response_spectrum import (  # noqa: E402
    ResponseSpectrum as ResponseSpectrum,
)
from ._response_spectrum import (
    response_spectrum as response_spectrum,
)
from ._response_spectrum import rotd50 as rotd50
from ._results import DECISION_WINDOW as DECISION_WINDOW  # noqa: E402
from ._results import (
    EventKind as EventKind,
)
from ._results import (
    History as History,
)
from ._results import (
    Outcome as Outcome,
)
from ._results import (
    Response as Response,
)
from ._results import (
    SolverOptions as SolverOptions,
)
from ._results import (
    Status as Status,
)
from ._simulate import (
    simulate as simulate,
)
from ._spectrum import OverturningSpectrum as OverturningSpectrum  # noqa: E402
from ._spectrum import (  # noqa: E402
    linearized_overturning_amplitude as linearized_overturning_amplitude,
)
from ._spectrum import overturning_spectrum as overturning_spectrum
from ._vertical import WithVertical as WithVertical

__version__ = _metadata.version("jaxrock")
