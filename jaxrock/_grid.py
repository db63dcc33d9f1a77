"""A map's grid: its cells and their pilots, the inputs of chosen cells, and
what identifies its chunks in a store."""

import abc
import hashlib
import json
import os

import jax
import numpy as np

from ._block import Block
from ._misc import broadcast_batch_shape
from ._model import initial_carry
from ._results import _max_steps_for
from ._scene import MotionLayout, prepare


def _leaf_digest(module) -> str:
    """A short fingerprint of a module's array leaves (to match a store)."""
    h = hashlib.sha256()
    for x in jax.tree_util.tree_leaves(module):
        h.update(np.ascontiguousarray(np.asarray(x, dtype=float)).tobytes())
    return h.hexdigest()[:16]


def _leaf_shapes(module) -> list[list[int]]:
    """The shapes of a module's array leaves (to match a store)."""
    return [list(np.shape(x)) for x in jax.tree_util.tree_leaves(module)]


# Packages whose classes a store's key names by description and form only
# (a class made by `type()` may name "abc" as its module: only `abc.ABC` is
# known there).
_KNOWN_CODE = ("jaxrock", "equinox", "builtins", "typing", "collections")


def _code_digest(*modules) -> str | None:
    """A short fingerprint of the code of the classes of `modules` defined
    outside jaxrock (a user's isolator or motion): their functions' bytecode,
    constants and names and their plain class values, not their file or
    lines (a notebook's cell has another file name in every session); None
    where there are none. A class edited and run again into a store is
    another map."""
    h, found = hashlib.sha256(), False
    for module in modules:
        for cls in type(module).__mro__:
            known = (cls.__module__ or "").split(".")[0] in _KNOWN_CODE
            if known or cls is abc.ABC:
                continue
            found = True
            h.update(cls.__qualname__.encode())
            for name, value in sorted(vars(cls).items()):
                if isinstance(value, property):
                    value = value.fget
                value = getattr(value, "__func__", value)  # static, class
                if hasattr(value, "__code__"):
                    h.update(name.encode())
                    _hash_code(h, value.__code__)
                elif isinstance(value, (bool, int, float, str, tuple)):
                    h.update(f"{name}={value!r}".encode())
    return h.hexdigest()[:16] if found else None


def _hash_code(h, code) -> None:
    h.update(code.co_code)
    h.update(repr((code.co_names, code.co_varnames)).encode())
    for c in code.co_consts:
        if hasattr(c, "co_code"):
            _hash_code(h, c)
        else:
            h.update(repr(c).encode())


def _cells_of(module, shape, index):
    """Every leaf broadcast to `shape`, flattened and taken at `index` (1-D)."""
    return jax.tree_util.tree_map(
        lambda x: np.broadcast_to(np.asarray(x), shape).reshape(-1)[index], module
    )


# Memory a map holds per cell on the host: inputs, indices, results and the
# chunks' carries (measured: about 0.5 kB a cell at 2,440 to 100,000 cells).
_BYTES_PER_CELL = 1024


def check_fits_in_memory(n: int) -> None:
    """`ValueError` before anything runs when a map of n cells cannot fit in
    half of this machine's memory."""
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return
    if n * _BYTES_PER_CELL > memory / 2:
        raise ValueError(
            f"a map of {n:,} cells needs about {n * _BYTES_PER_CELL / 2**30:.1f} GiB; "
            f"at most {int(memory / 2 / _BYTES_PER_CELL):,} cells fit in this "
            "machine's memory: split `slenderness` or `size` into smaller maps"
        )


def _initial_carry(block, base, motion, one_base):
    """`initial_carry` in the scene of a chunk (`map_chunk`: the signal
    prepared for `one_base`, the base of every cell or None). One function:
    `jax.eval_shape` traces it once per shape."""
    return initial_carry(block, base, prepare(motion, one_base))


class Grid:
    """The cells of a map and their pilots.

    Cells run over (base batch, motion batch, restitution, slenderness, size)
    in C order; one pilot per (base, motion, slenderness) runs the shared
    translation phase (see `_chunk.map_chunk`), which the coefficient of
    restitution does not enter. `restitution` is None (the momentum model's
    e), or ("restitution_factor" or "restitution", a scalar or 1-D array of
    values: the blocks' own, an axis if 1-D). `friction` is None (no check
    of sliding) or the blocks' coefficient of friction, one number (cells
    and pilots: sliding in translation is the pilots' to find). `inputs`
    gives the per-cell arrays of chosen cells."""

    def __init__(self, lam, r, base, motion, restitution=None, friction=None):
        self.lam, self.r, self.base, self.motion = lam, r, base, motion
        self.restitution = restitution
        self.friction = friction
        self.motion_shape = motion.batch_shape
        self.motion_names = motion.names() if self.motion_shape else None
        self.layout = MotionLayout.of(motion)
        self.base_shape = broadcast_batch_shape(base)
        values = () if restitution is None else np.shape(restitution[1])
        self.restitution_shape = values
        self.shape = self.base_shape + self.motion_shape + values + (lam.size, r.size)
        self.n = int(np.prod(self.shape))
        n_base, n_motion = (
            int(np.prod(self.base_shape)),
            int(np.prod(self.motion_shape)),
        )
        n_e = int(np.prod(values))
        ib, im, ie, il, ir = np.unravel_index(
            np.arange(self.n), (n_base, n_motion, n_e, lam.size, r.size)
        )
        self.pilots = n_base * n_motion * lam.size
        self.pilot_of_cell = (ib * n_motion + im) * lam.size + il
        pb, pm, pl = np.unravel_index(
            np.arange(self.pilots), (n_base, n_motion, lam.size)
        )
        self.pilot_inputs = self.inputs(pb, pm, None, pl, np.zeros_like(pl))
        self.cell_inputs = self.inputs(ib, im, ie, il, ir)

    def inputs(self, ib, im, ie, il, ir):
        """(slenderness, size, base, motion, own) of the cells (ib, im, ie,
        il, ir) (1-D index arrays); the motion is None for one motion of every
        cell, the index into the suite for a suite of records; `own` the
        blocks' own `Block` keywords (a dict of per-cell arrays, None if none):
        the restitution (`restitution_factor` or `restitution`; none for
        pilots, `ie` None) and the `friction`."""
        if self.layout is MotionLayout.ONE_RECORD:
            motion = None
        elif self.layout is MotionLayout.SUITE:
            motion = im
        else:
            motion = _cells_of(self.motion, self.motion_shape, im)
        own = {}
        if self.restitution is not None and ie is not None:
            name, values = self.restitution
            own[name] = np.reshape(values, -1)[ie]
        if self.friction is not None:
            own["friction"] = np.full(np.shape(il), self.friction)
        return (
            self.lam[il],
            self.r[ir],
            _cells_of(self.base, self.base_shape, ib),
            motion,
            own or None,
        )

    def blank_carries(self):
        """Zero carries of every pilot (the `shared` input of the pilot pass)."""
        first = lambda tree: jax.tree_util.tree_map(lambda x: x[0], tree)  # noqa: E731
        _, _, base, motion, _ = self.pilot_inputs
        if self.layout is MotionLayout.ONE_RECORD:
            motion = self.motion
        elif self.layout is MotionLayout.SUITE:
            motion = self.motion.select(0)
        else:
            motion = first(motion)
        one_base = self.base if self.base_shape == () else None
        proto = jax.eval_shape(
            _initial_carry,
            Block(self.lam[0], self.r[0], friction=self.friction),
            first(base),
            motion.unlabeled(),
            one_base,
        )
        return jax.tree_util.tree_map(
            lambda s: np.zeros((self.pilots,) + s.shape, s.dtype), proto
        )

    def store_key(self, duration, chunk, opts) -> str:
        """What identifies the map's chunks in a store (the keys of a map
        with neither `until_decided`, its own restitution, a friction nor a
        step limit other than its motion's default are those of the maps
        before any existed: their stores resume)."""
        extra = {}
        if opts.max_steps != _max_steps_for(self.motion, None):
            extra["max_steps"] = opts.max_steps
        if bool(opts.until_decided):
            extra["until_decided"] = True
        if self.restitution is not None:
            name, values = self.restitution
            extra[name] = np.asarray(values, dtype=float).tolist()
        if self.friction is not None:
            extra["friction"] = self.friction
        # The leaves' digest concatenates their values: a batch's shapes tell
        # period [2, 2.5] with damping 0.35 from period 2 with damping
        # [2.5, 0.35] (and transposed axes of two parameters).
        if self.base_shape:
            extra["base_shapes"] = _leaf_shapes(self.base)
        if self.motion_shape and self.layout is MotionLayout.PER_CELL:
            extra["motion_shapes"] = _leaf_shapes(self.motion)
        code = _code_digest(self.base, self.motion)
        if code is not None:
            extra["code"] = code
        tolerances = (opts.rtol, opts.atol, opts.rest_tolerance, opts.step)
        return json.dumps(
            dict(
                slenderness=self.lam.tolist(),
                size=self.r.tolist(),
                base=self.base.describe(),
                motion=self.motion.describe(),
                base_leaves=_leaf_digest(self.base),
                # static fields
                base_form=str(jax.tree_util.tree_structure(self.base)),
                motion_leaves=_leaf_digest(self.motion),
                duration=float(duration),
                chunk=chunk,
                options=_leaf_digest(tolerances),
                solver=repr(opts.solver),
                max_segments=opts.max_segments,
                layout="cells dealt by start",  # chunks list their cells
            )
            | extra
        )
