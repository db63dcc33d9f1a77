"""Behavior maps: one analysis per (slenderness, size) cell, vmapped and chunked."""

import json
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._block import Block
from ._ground import AbstractGroundMotion, MPPulse, Record
from ._isolators import AbstractIsolator, FixedBase, FrictionPendulum, LinearIsolator
from ._misc import as_float, positive
from ._simulate import Outcome, SolverOptions, Status, _check_types, run

_FIELDS = ("outcome", "max_rotation", "max_base_displacement", "impacts",
           "uplift_time", "status", "steps", "segments")


@eqx.filter_jit
def _map_chunk(slenderness, size, base, motion, duration, opts):
    """A chunk of lanes (1-D arrays of equal length): one compile per base type."""
    return jax.vmap(lambda lam, r: run(Block(lam, r), base, motion, duration, opts))(
        slenderness, size
    )


def describe_base(base: AbstractIsolator) -> str:
    if isinstance(base, FixedBase):
        return "fixed base"
    if isinstance(base, LinearIsolator):
        return (f"linear isolator (T_s = {float(base.period):g} s, "
                f"xi = {float(base.damping):g}, mass ratio {float(base.mass_ratio):g})")
    if isinstance(base, FrictionPendulum):
        return (f"friction pendulum (mu = {float(base.friction):g}, "
                f"R = {float(base.radius):g} m, mass ratio {float(base.mass_ratio):g})")
    return type(base).__name__


def describe_motion(motion: AbstractGroundMotion) -> str:
    if isinstance(motion, MPPulse):
        return (f"MP pulse (A = {float(motion.amplitude):g} m/s, "
                f"f_p = {float(motion.frequency):g} Hz, gamma = {float(motion.gamma):g}, "
                f"nu = {float(motion.phase):g} deg)")
    if isinstance(motion, Record):
        return (f"record ({motion.samples.shape[0]} samples, "
                f"dt = {float(motion.dt):g} s)")
    return type(motion).__name__


class BehaviorMap(eqx.Module):
    """Results over a grid: arrays of shape (n_slenderness, n_size).

    `outcome` holds `Outcome` codes and `status` `Status` codes per cell; the other
    fields are those of `Response`. `base` and `motion` describe what produced it;
    `seconds` is the wall time of the computation.
    """

    slenderness: np.ndarray
    size: np.ndarray
    outcome: np.ndarray
    max_rotation: np.ndarray
    max_base_displacement: np.ndarray
    impacts: np.ndarray
    uplift_time: np.ndarray
    status: np.ndarray
    steps: np.ndarray
    segments: np.ndarray
    base: str
    motion: str
    seconds: float

    def counts(self) -> dict[str, int]:
        """Cells per outcome, plus cells whose analysis did not converge."""
        out = {o.name.lower(): int(np.sum(self.outcome == o)) for o in Outcome}
        out["not_converged"] = int(np.sum(self.status != Status.SUCCESS))
        return out

    def summary(self) -> str:
        c = self.counts()
        text = (f"{self.outcome.size} analyses in {self.seconds:.2f} s: "
                f"{c['no_rocking']} no rocking, {c['rocking']} rocking, "
                f"{c['overturned']} overturned")
        if c["not_converged"]:
            text += f", {c['not_converged']} NOT CONVERGED (see status)"
        return text + f" [{self.motion}; {self.base}]"

    def save(self, path) -> None:
        """Write the arrays and metadata to an `.npz` file."""
        meta = json.dumps({"base": self.base, "motion": self.motion,
                           "seconds": self.seconds})
        arrays = {k: getattr(self, k) for k in ("slenderness", "size") + _FIELDS}
        np.savez_compressed(path, metadata=np.array(meta), **arrays)

    @classmethod
    def load(cls, path) -> "BehaviorMap":
        """Read a map written by `save`."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["metadata"]))
            arrays = {k: data[k] for k in ("slenderness", "size") + _FIELDS}
        return cls(**arrays, **meta)


def behavior_map(
    slenderness,
    size,
    base: AbstractIsolator,
    motion: AbstractGroundMotion,
    *,
    duration: float | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-10,
    chunk_size: int | None = 64,
    progress: bool | None = None,
    max_segments: int = 2000,
    rest_tolerance: float = 1e-6,
) -> BehaviorMap:
    """Classify every block of the grid `slenderness` x `size` (1-D arrays).

    Every cell is the exact analysis of `simulate`. Lanes run `chunk_size` at a
    time through one compiled, vmapped function (a batched while loop waits for
    its slowest lane, so small chunks waste less); `None` runs all at once.
    `progress` shows a tqdm bar (default: when there is more than one chunk).
    New grids, pulses or isolator parameters of the same shapes reuse the compile.
    """
    _check_types(None, base, motion)
    lam = np.atleast_1d(np.asarray(slenderness, dtype=float))
    r = np.atleast_1d(np.asarray(size, dtype=float))
    if lam.ndim != 1 or r.ndim != 1:
        raise ValueError("`slenderness` and `size` must be 1-D arrays")
    positive("slenderness", lam)
    positive("size", r)
    if duration is None:
        duration = motion.end_time + 5.0
    positive("duration", duration)
    if chunk_size is not None and chunk_size < 1:
        raise ValueError(f"`chunk_size` must be >= 1 or None, got {chunk_size}")
    opts = SolverOptions(rtol, atol, 16384, max_segments, rest_tolerance)
    lanes_l, lanes_r = (x.ravel() for x in np.meshgrid(lam, r, indexing="ij"))
    n = lanes_l.size
    chunk = n if chunk_size is None else min(chunk_size, n)
    pad = (-n) % chunk
    # Padding repeats the last cell, so every chunk has one shape (one compile).
    lanes_l = np.concatenate([lanes_l, np.full(pad, lanes_l[-1])])
    lanes_r = np.concatenate([lanes_r, np.full(pad, lanes_r[-1])])
    starts = range(0, n + pad, chunk)
    if progress is None:
        progress = len(starts) > 1
    if progress:
        from tqdm.auto import tqdm

        starts = tqdm(starts, desc="behavior map", unit="chunk")
    duration = as_float(duration)
    t = time.perf_counter()
    parts = []
    for i in starts:
        out = _map_chunk(jnp.asarray(lanes_l[i : i + chunk]),
                         jnp.asarray(lanes_r[i : i + chunk]),
                         base, motion, duration, opts)
        parts.append(jax.device_get(out))
    seconds = time.perf_counter() - t
    fields = {
        k: np.concatenate([getattr(p, k) for p in parts])[:n].reshape(lam.size, r.size)
        for k in _FIELDS
    }
    return BehaviorMap(slenderness=lam, size=r, **fields, base=describe_base(base),
                       motion=describe_motion(motion), seconds=seconds)
