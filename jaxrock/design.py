"""Isolator design: objectives over blocks x motions, an Optax loop (forward mode)."""

from ._design import (
    DesignResult as DesignResult,
)
from ._design import (
    isolator_objective as isolator_objective,
)
from ._design import (
    responses as responses,
)
from ._design import (
    tune_isolator as tune_isolator,
)
