"""Isolator design: objectives over blocks x motions and an Optax loop (forward mode)."""

from ._design import (
    DesignResult as DesignResult,
    isolator_objective as isolator_objective,
    responses as responses,
    tune_isolator as tune_isolator,
)
