"""Behavior maps: one analysis per (slenderness, size) cell, vmapped and chunked."""

import hashlib
import json
import os
import threading
import time
import zipfile
from concurrent.futures import Executor, ThreadPoolExecutor

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _cache, _layout
from ._block import Block
from ._dynamics import Phase
from ._executor import check_executor, run_tasks
from ._files import atomic_write
from ._flat import flat_step
from ._free import free_rocking, free_rocking_ready
from ._ground import AbstractGroundMotion
from ._isolators import AbstractIsolator
from ._labeled import ATTRS, Coordinates, coordinates, dataset, read, suffix, write
from ._misc import (
    as_float,
    broadcast_batch_shape,
    grid_axis,
    one_real_number,
    positive,
    where_lanes,
)
from ._model import (
    Carry,
    check_base_and_motion,
    initial_carry,
    is_active,
    response,
    with_start_conditions,
)
from ._results import (
    ATOL,
    MAX_SEGMENTS,
    RESPONSE_FIELDS,
    REST_TOLERANCE,
    RTOL,
    Outcome,
    SolverOptions,
    Status,
)
from ._store import ChunkStore
from ._xla import compiler_accepts

# The name scope of the loop that steps a chunk's lanes (`_Chunk.steps`): on
# the CPU, XLA compiles it as one kernel (see `_xla.py`).
STEP_LOOP = "lane_steps"
_FIELDS = RESPONSE_FIELDS


class _Lanes(eqx.Module):
    """The state of a chunk's loop: each lane's carry, cell (n: idle) and
    inputs, the queue's next cell, the results written so far (one per cell),
    the lanes that finished in the last steps, and the lane-steps executed and
    those that advanced an analysis."""

    carry: Carry
    cell: jax.Array
    queue: jax.Array
    out: Carry
    executed: jax.Array
    useful: jax.Array
    per_lane: tuple
    finished: jax.Array


@eqx.filter_jit
def _map_chunk(
    slenderness,
    size,
    base,
    motion,
    motion_index,
    shared,
    one_base,
    duration,
    opts,
    count,
    pilot,
    loop: _layout.Loop,
):
    """Analyse the first `count` cells of a chunk on `loop.lanes` lanes that
    refill from a queue.

    `slenderness`, `size`, every leaf of `base` and of `shared` carry one
    leading cell axis; so do those of `motion`, unless it is one motion for all
    cells (a record, `shared_by_cells`) or a suite of records, of which
    `motion_index` (else None) gives each cell's record; `one_base` is the
    base of every cell without the cell axis, if they share one (else None:
    an ensemble of bases); cells from `count` on
    are padding and never analysed (`count` is traced: one compile per chunk
    shape). Each iteration of the vmapped loop advances every lane by one step
    attempt (`flat_step`); a lane whose analysis is done writes its result and
    takes the chunk's next cell at once, so lanes wait for each other only at
    the chunk's end. (An inner loop steps the lanes until one finishes and the
    outer one refills: no `lax.cond` in every step, whose outputs XLA copies.)

    The pure-translation phase is shared (see `behavior_map`): until it uplifts a
    block moves with its base as one body, and neither the steps nor the events
    of that phase depend on the block. With `pilot` (traced: the same compile)
    each cell runs from t = 0 only up to the attempt in which it uplifts, or that
    reaches the end of the shaking or ends the analysis, and returns its carry
    before that attempt. Without, each cell starts from `shared` (such a carry
    of a pilot of its slenderness, base and motion), or from t = 0 if it
    uplifts at once, and redoes that attempt itself: the same steps as its
    own analysis from t = 0.

    On a base whose free rocking has a closed form (a fixed base), a lane that
    rocks once the ground is still (below the separatrix, on the near side of
    its corner) finishes at once; after the loop `free_rocking` completes all
    such cells of the chunk together.

    Returns the responses and carries (one per cell), the lane-steps executed
    (iterations times lanes) and those that advanced an analysis.
    """
    motion = motion.with_peaks()
    if one_base is not None:  # (a linear isolator's response to a record)
        motion = motion.with_translation(one_base)
    chunk = _Chunk(
        slenderness,
        size,
        base,
        motion,
        motion_index,
        shared,
        duration,
        opts,
        pilot,
        loop.one_event_batch,
    )
    n, width = chunk.n, min(loop.lanes, chunk.n)
    # Every lane starts idle and finished: the loop's first `refill` gives
    # them the first cells.
    idle = jnp.full(width, n)
    per_lane0 = _zeros_of(chunk.gather, idle)
    carry0 = _zeros_of(chunk.start, idle, per_lane0)
    zero = jnp.asarray(0)
    state = _Lanes(
        carry=carry0,
        cell=idle,
        queue=zero,
        out=jax.tree_util.tree_map(
            lambda x: jnp.zeros((n,) + x.shape[1:], x.dtype), carry0
        ),
        executed=zero,
        useful=zero,
        per_lane=per_lane0,
        finished=jnp.ones(width, dtype=bool),
    )
    state = jax.lax.while_loop(
        lambda s: jnp.any(s.cell < n) | (s.queue < count),
        lambda s: chunk.steps(chunk.refill(s, count)),
        state,
    )
    return (*chunk.responses(state.out), state.executed, state.useful)


def _zeros_of(f, *args):
    """Zeros shaped as the output of f(*args), which is traced, not computed."""
    return jax.tree_util.tree_map(
        lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(f, *args)
    )


class _Chunk(eqx.Module):
    """A chunk's cells and what its lanes share (the arguments of `_map_chunk`
    but `count` and the loop's lanes), and the steps of its loop.

    The motion is one of three: per cell (its parameters carry the cell axis),
    one record for every cell (`shared_by_cells`), or a suite of records with
    `motion_index` giving each cell's record; the lanes read a record or a
    suite in place (a suite's lane holds its row, `Record.row`), with its
    table of peaks (`with_peaks`).
    """

    slenderness: jax.Array
    size: jax.Array
    base: AbstractIsolator
    motion: AbstractGroundMotion
    motion_index: jax.Array | None
    shared: Carry
    duration: jax.Array
    opts: SolverOptions
    pilot: jax.Array
    one_event_batch: bool = eqx.field(static=True)

    @property
    def n(self) -> int:
        return self.slenderness.shape[0]

    @property
    def suite(self) -> bool:
        return self.motion_index is not None

    @property
    def one_motion(self) -> bool:
        return not self.suite and self.motion.shared_by_cells

    @property
    def axes(self) -> tuple:
        """The `jax.vmap` in_axes of a lane's (block, base, motion)."""
        if self.suite:
            return 0, 0, self.motion.row_axes()
        return 0, 0, None if self.one_motion else 0

    def gather(self, cell):
        """The cells' block, base and motion, each with a lane axis (the motion
        None for one motion of every lane, the suite's rows for a suite: see
        `inputs`)."""
        cell = jnp.minimum(cell, self.n - 1)
        take = lambda tree: jax.tree_util.tree_map(lambda x: x[cell], tree)  # noqa: E731
        lane_motion = None
        if self.suite:
            lane_motion = self.motion_index[cell]
        elif not self.one_motion:
            lane_motion = take(self.motion)
        return (
            Block(self.slenderness[cell], self.size[cell]),
            take(self.base),
            lane_motion,
        )

    def inputs(self, per_lane):
        """`gather`'s output as `flat_step` takes it (batched as `axes` says)."""
        block, lane_base, lane_motion = per_lane
        if self.suite:
            return block, lane_base, self.motion.row(lane_motion)
        return block, lane_base, self.motion if self.one_motion else lane_motion

    def start(self, cell, per_lane):
        """The lanes' first carries: from t = 0 (pilots, or a cell that uplifts
        at once) or from their pilot's carry (`shared`); idle lanes done."""
        c = jax.vmap(initial_carry, in_axes=self.axes)(*self.inputs(per_lane))
        index = jnp.minimum(cell, self.n - 1)
        later = jax.tree_util.tree_map(lambda x: x[index], self.shared)
        c = where_lanes(c.rocked | self.pilot, c, later)
        # Of the cell's own block (its pilot's has another size).
        c = jax.vmap(with_start_conditions, in_axes=(0,) + self.axes)(
            c, *self.inputs(per_lane)
        )
        return eqx.tree_at(lambda c: c.done, c, c.done | (cell >= self.n))

    def closed_form(self, c, block, lane_motion):
        """The lanes finished in closed form (`_free.py`): free rocking on a
        fixed base once the ground is still."""
        if not self.base.free_rocking_closed_form:
            return jnp.zeros_like(c.done)
        return free_rocking_ready(c, block, lane_motion.end_time)  # elementwise

    def steps(self, state: _Lanes) -> _Lanes:
        """Step every lane until one or more finish: the lanes whose analysis is
        done, or with `pilot` whose shared phase ends (these keep their carry
        from before that attempt). No cell changes here, so the lanes' inputs
        are gathered once (in `refill`), not at every step."""
        block, lane_base, lane_motion = self.inputs(state.per_lane)
        opts, pilot, width = self.opts, self.pilot, state.cell.shape[0]

        def body(s: _Lanes) -> _Lanes:
            new, a = flat_step(
                s.carry,
                block,
                lane_base,
                lane_motion,
                self.duration,
                opts,
                self.axes,
                self.one_event_batch,
            )
            taken = new.steps - s.carry.steps
            ended = new.done | (new.segments >= opts.max_segments)
            ended = ended | self.closed_form(new, block, lane_motion)
            leaves = new.rocked | (a.t1 >= lane_motion.end_time)  # the shared phase
            finished = (s.cell < self.n) & (ended | (pilot & leaves))
            return eqx.tree_at(
                lambda s: (s.carry, s.finished, s.executed, s.useful),
                s,
                (
                    where_lanes(pilot & finished, s.carry, new),
                    finished,
                    s.executed + jnp.max(taken) * width,
                    s.useful + jnp.sum(taken),
                ),
            )

        state = eqx.tree_at(lambda s: s.finished, state, jnp.zeros_like(state.finished))
        with jax.named_scope(STEP_LOOP):  # a name to find it by in XLA's programs
            return jax.lax.while_loop(
                lambda s: ~jnp.any(s.finished) & jnp.any(s.cell < self.n), body, state
            )

    def refill(self, state: _Lanes, count) -> _Lanes:
        """The lanes that finished write their results (idle lanes nowhere)
        and take the queue's next cells (of the first `count`)."""
        finished, cell, c = state.finished, state.cell, state.carry
        index = jnp.where(finished, cell, self.n)  # other lanes write nowhere
        out = jax.tree_util.tree_map(
            lambda o, r: o.at[index].set(r, mode="drop"), state.out, c
        )
        cell = jnp.where(finished, state.queue + jnp.cumsum(finished) - 1, cell)
        cell = jnp.where(finished & (cell >= count), self.n, cell)
        fresh = self.gather(cell)
        return _Lanes(
            carry=where_lanes(finished, self.start(cell, fresh), c),
            cell=cell,
            queue=state.queue + jnp.sum(finished),
            out=out,
            executed=state.executed,
            useful=state.useful,
            per_lane=where_lanes(finished, fresh, state.per_lane),
            finished=finished,
        )

    def responses(self, carries: Carry):
        """The cells' responses and carries. On a fixed base, the lanes that
        `closed_form` ended (not done, within their segments, rocking; not
        pilots, whose responses are not used) finish in closed form."""
        blocks = Block(self.slenderness, self.size)
        final = carries
        if self.base.free_rocking_closed_form:
            ready = is_active(carries, self.opts)
            ready = ready & ~self.pilot & (carries.phase != Phase.TRANSLATION)
            final = free_rocking(
                carries, blocks, self.base, self.duration, self.opts, ready
            )
        responses = jax.vmap(response, in_axes=(0, 0, None))(final, blocks, self.opts)
        return responses, carries


class BehaviorMap(eqx.Module):
    """The results of `behavior_map`: one analysis per block of a grid.

    The grid's cells are the blocks (slenderness lambda = h / b, size r in m)
    of `slenderness` x `size`. Every per-cell field has shape
    (..., n_slenderness, n_size), with leading axes for a batch of bases, then
    of motions; it holds the value of the same field of `Response` for that
    cell. `save` writes a map to a file and `load` reads it back.

    Attributes:
        slenderness: the grid's values of lambda = h / b (-), 1-D.
        size: the grid's values of r, the half-diagonal (m), 1-D.
        outcome: the `Outcome` codes.
        max_rotation: max |theta| / alpha (-), pi / (2 alpha) where the block
            overturns.
        max_base_displacement: max |u| (m); 0 on a fixed base.
        impacts: the numbers of impacts.
        uplift_time: the time of the first uplift (s); NaN where none.
        status: the `Status` codes; anything but SUCCESS marks a cell whose
            numbers are not final.
        steps: the solver's steps of each analysis (on a fixed base, of its
            integrated part: free rocking after the excitation is finished in
            closed form).
        segments: the segments (events) of each analysis.
        base: a description of the base.
        motion: a description of the motion.
        seconds: the wall time of the computation (s), compilation included on
            a first call.
        lane_efficiency: the share (0 to 1) of the executed lane-steps that
            advanced an unfinished analysis (vmapped lanes wait for the
            slowest one).
        motion_names: the records' names of a map under a suite of records
            (its leading motion axis); None otherwise.
        coordinates: the names of the leading axes and the parameters of the
            base and the motion along them (`Coordinates`); None for a map
            read from a file that does not hold them.

    Examples:
        >>> import jaxrock as jr
        >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
        ...                      jr.near_fault_pulse("Northridge JFA/SN"))
        >>> bm.outcome
        array([[0, 0],
               [2, 1]])
        >>> bm.max_rotation.round(3)
        array([[0.   , 0.   ],
               [9.511, 0.036]])
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
    lane_efficiency: float = float("nan")
    # The records' names of a map under a suite (its leading motion axis).
    motion_names: tuple | None = None
    coordinates: Coordinates | None = None

    def select(self, index: int) -> "BehaviorMap":
        """The map at `index` of its leading axis (a suite's record, an
        ensemble's isolator or pulse), labelled with the record's name; its
        `coordinates` hold that member's parameters, and a map under a suite
        keeps the records' names unless the axis is the suite's."""
        if self.outcome.ndim < 3:
            raise ValueError("the map has no leading batch axis to select from")
        fields = {k: getattr(self, k)[index] for k in _FIELDS}
        names, c = self.motion_names, self._coordinates()
        if self.coordinates is None:  # (read from a file without them) a guess
            on_records = names is not None and len(names) == self.outcome.shape[0]
        else:
            on_records = c.dims[0].startswith("record")
        one = on_records and names is not None and len(names) == self.outcome.shape[0]
        member = f" [{_member_label(c, index) or index}]"
        on_bases = c.dims[0].startswith("base")
        motion = names[index] if one else self.motion + ("" if on_bases else member)
        return BehaviorMap(
            slenderness=self.slenderness,
            size=self.size,
            **fields,
            base=self.base + (member if on_bases else ""),
            motion=motion,
            seconds=self.seconds,
            lane_efficiency=self.lane_efficiency,
            motion_names=None if on_records else names,
            coordinates=c.select(index),
        )

    def _coordinates(self) -> Coordinates:
        return self.coordinates or Coordinates.unlabeled(self.outcome.ndim - 2)

    def counts(self) -> dict[str, int]:
        """The number of cells per outcome, and of cells that did not converge.

        Returns:
            A dict: "no_rocking", "rocking" and "overturned" count the cells of
            each `Outcome`; "not_converged" the cells whose status is not
            SUCCESS (counted under their outcome as well).

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> bm.counts()
            {'no_rocking': 2, 'rocking': 1, 'overturned': 1, 'not_converged': 0}
        """
        out = {o.name.lower(): int(np.sum(self.outcome == o)) for o in Outcome}
        out["not_converged"] = int(np.sum(self.status != Status.SUCCESS))
        return out

    def summary(self) -> str:
        """One line: the analyses, their wall time (s) and the cells per outcome.

        Cells that did not converge are flagged; the motion and the base close
        the line.

        Returns:
            The line, a str.

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> print(bm.summary())  # doctest: +ELLIPSIS
            4 analyses in ... s: 2 no rocking, 1 rocking, 1 overturned [MP pulse ...]
        """
        c = self.counts()
        text = (
            f"{self.outcome.size} analyses in {self.seconds:.2f} s: "
            f"{c['no_rocking']} no rocking, {c['rocking']} rocking, "
            f"{c['overturned']} overturned"
        )
        if c["not_converged"]:
            text += f", {c['not_converged']} NOT CONVERGED (see status)"
        return text + f" [{self.motion}; {self.base}]"

    def to_xarray(self):
        """The map as an `xarray.Dataset` with named dimensions.

        Dimensions: the leading (batch) axes of `coordinates` ("base", then
        "motion" for a batch of pulses or "record" for a suite of records),
        then "slenderness" and "size". Coordinates: the grid (slenderness
        lambda = h / b, -; size r, m) and the parameters of the base and the
        motion along the batch axes, with their SI units in `attrs` (e.g.
        `period` (s) of a batch of `LinearIsolator`, `amplitude` (m/s) of a
        batch of pulses, `record` the records' names), 0-d where one value. A
        1-D coordinate of distinct values is an index: `ds.sel(period=2.0)`.
        Data variables: the per-cell fields, their meanings and units in
        `attrs` (`outcome` and `status` list their codes as `flag_values`
        and `flag_meanings`). Attributes: `base` and `motion` (descriptions),
        `seconds` (s), `lane_efficiency` and, under a suite, `motion_names`.

        Needs xarray (`pip install "jaxrock[xarray]"`).

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> ds = bm.to_xarray()
            >>> ds.outcome.dims, int(ds.outcome.sel(slenderness=6.0, size=0.5))
            (('slenderness', 'size'), 2)
            >>> float(ds.frequency), ds.frequency.attrs["units"]  # the pulse's f_p
            (0.33, 'Hz')
        """
        c = self._coordinates()
        dims = c.dims + ("slenderness", "size")
        coords = {
            k: ((k,), getattr(self, k), ATTRS[k]) for k in ("slenderness", "size")
        }
        return dataset(
            {k: (dims, getattr(self, k)) for k in _FIELDS},
            coords | c.coords,
            self._attributes(),
        )

    def _attributes(self) -> dict:
        """The metadata: base, motion, seconds, lane_efficiency, motion_names
        (when a suite's, None as "")."""
        out = dict(
            base=self.base,
            motion=self.motion,
            seconds=float(self.seconds),
            lane_efficiency=float(self.lane_efficiency),
        )
        if self.motion_names is not None:
            out["motion_names"] = ["" if n is None else n for n in self.motion_names]
        return out

    @classmethod
    def from_xarray(cls, ds) -> "BehaviorMap":
        """The map of a Dataset of `BehaviorMap.to_xarray` (or read from its
        file).

        Raises:
            ValueError: a Dataset without the map's variables or attributes
                (base, motion, seconds), or whose arrays disagree (see
                `load`).

        Examples:
            >>> import jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> jr.BehaviorMap.from_xarray(bm.to_xarray()).counts() == bm.counts()
            True
        """
        names = ("slenderness", "size") + _FIELDS
        missing = [k for k in names if k not in ds.variables]
        missing += [k for k in ("base", "motion", "seconds") if k not in ds.attrs]
        if missing:
            raise ValueError(f"missing {', '.join(missing)}")
        arrays = {k: ds[k].values for k in names}
        _check_map_arrays(arrays)
        dims = ds["outcome"].dims[:-2]
        suite = ds.attrs.get("motion_names")
        return cls(
            **arrays,
            base=str(ds.attrs["base"]),
            motion=str(ds.attrs["motion"]),
            seconds=float(ds.attrs["seconds"]),
            lane_efficiency=float(ds.attrs.get("lane_efficiency", np.nan)),
            motion_names=None
            if suite is None
            else tuple(str(n) or None for n in np.atleast_1d(suite)),
            coordinates=Coordinates.from_dataset(ds, dims, ("slenderness", "size")),
        )

    def save(self, path) -> None:
        """Write the map to a file, in the format its suffix names.

        `.npz`: a compressed NumPy file (every array, and the metadata as
        JSON); `.nc`: NetCDF-4 (by h5netcdf); `.zarr`: a Zarr store (a
        folder, replaced if it exists). NetCDF and Zarr hold the Dataset of
        `to_xarray` and need `pip install "jaxrock[xarray]"`. Every format
        holds the arrays, the batch axes' coordinates and the metadata (base,
        motion, seconds, lane_efficiency, motion_names); `BehaviorMap.load`
        reads them back.

        Args:
            path: the file's path (str or path-like), ending in `.npz`, `.nc`
                or `.zarr`; NumPy appends `.npz` to a name without a suffix.

        The file is written under a temporary name beside `path` and renamed
        over it once whole (`.zarr`: the folder): a full disk or an
        interruption leaves a file already at `path` as it was.

        Raises:
            ValueError: any other suffix, or a `.zarr` path that exists and is
                not a Zarr store.
            OSError: the file cannot be written (a full disk, no permission);
                the message names `path`.

        Examples:
            >>> import os, tempfile, jaxrock as jr
            >>> bm = jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                      jr.near_fault_pulse("Northridge JFA/SN"))
            >>> path = os.path.join(tempfile.mkdtemp(), "map.npz")
            >>> bm.save(path)
            >>> jr.BehaviorMap.load(path).counts() == bm.counts()
            True
        """
        kind = suffix(path)
        if kind != ".npz":
            write(self.to_xarray(), path, kind)
            return
        meta = self._attributes() | {
            "motion_names": self.motion_names,
            "coordinates": None
            if self.coordinates is None
            else self.coordinates.to_json(),
        }
        # Strict JSON: NaN as null.
        meta = {k: None if v != v else v for k, v in meta.items()}
        arrays = {k: getattr(self, k) for k in ("slenderness", "size") + _FIELDS}
        metadata = json.dumps(meta, allow_nan=False)
        if not str(path).endswith(".npz"):  # the name NumPy would write
            path = f"{path}.npz"
        atomic_write(
            path,
            lambda tmp: np.savez_compressed(tmp, metadata=np.array(metadata), **arrays),
        )

    @classmethod
    def load(cls, path) -> "BehaviorMap":
        """Read a map written by `BehaviorMap.save` (`.npz`, `.nc` or `.zarr`).

        Args:
            path: the file's path (str or path-like).

        Returns:
            The `BehaviorMap`, with the arrays, coordinates and metadata saved.

        Raises:
            ValueError: a suffix other than `.npz`, `.nc` and `.zarr`, or a
                file that is not such a map (the message names it): missing,
                unreadable or truncated, without some arrays or metadata, with
                arrays whose shapes disagree, or with outcome or status codes
                out of range.

        Examples:
            >>> import os, tempfile, jaxrock as jr
            >>> path = os.path.join(tempfile.mkdtemp(), "map.npz")
            >>> jr.behavior_map([3.0, 6.0], [0.5, 2.0], jr.FixedBase(),
            ...                 jr.near_fault_pulse("Northridge JFA/SN")).save(path)
            >>> bm = jr.BehaviorMap.load(path)
            >>> bm.outcome.shape, bm.base
            ((2, 2), 'fixed base')
        """
        kind = suffix(path)
        try:
            if kind != ".npz":
                return cls.from_xarray(read(path, kind))
            return cls._load_npz(path)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
            raise ValueError(
                f"{str(path)!r} is not a behavior map written by "
                f"BehaviorMap.save: {err}"
            ) from None

    @classmethod
    def _load_npz(cls, path) -> "BehaviorMap":
        names = ("slenderness", "size") + _FIELDS
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in ("metadata",) + names if k not in data.files]
            if missing:
                raise ValueError(f"missing {', '.join(missing)}")
            meta = json.loads(str(data["metadata"]))
            arrays = {k: data[k] for k in names}
        if not isinstance(meta, dict) or not {"base", "motion", "seconds"} <= set(meta):
            raise ValueError("its metadata lacks base, motion or seconds")
        _check_map_arrays(arrays)
        out = _metadata(meta)
        if isinstance(meta.get("coordinates"), dict):
            c = Coordinates.from_json(meta["coordinates"])
            if len(c.dims) != arrays["outcome"].ndim - 2:
                raise ValueError(f"coordinates name {len(c.dims)} leading axes")
            out["coordinates"] = c
        return cls(**arrays, **out)


def _metadata(meta: dict) -> dict:
    """The fields of a map file's metadata: base and motion (strings),
    seconds and lane_efficiency (numbers; null: NaN), motion_names (a list
    of strings or nulls); `ValueError` naming a field of another type."""
    out = {}
    for k in ("base", "motion"):
        if not isinstance(meta[k], str):
            raise ValueError(f"its metadata's {k} is not a string: {meta[k]!r}")
        out[k] = meta[k]
    for k in ("seconds", "lane_efficiency"):
        v = meta.get(k, float("nan"))
        v = float("nan") if v is None else v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"its metadata's {k} is not a number: {v!r}")
        out[k] = float(v)
    names = meta.get("motion_names")
    if names is not None:
        named = isinstance(names, list) and all(
            n is None or isinstance(n, str) for n in names
        )
        if not named:
            raise ValueError(
                f"its metadata's motion_names is not a list of strings: {names!r}"
            )
        out["motion_names"] = tuple(names)
    return out


def _check_map_arrays(arrays: dict) -> None:
    """`ValueError` unless a map's arrays agree: 1-D axes, every field of shape
    (..., n_slenderness, n_size), known outcome and status codes."""
    lam, r = arrays["slenderness"], arrays["size"]
    if lam.ndim != 1 or r.ndim != 1:
        raise ValueError("slenderness and size must be 1-D")
    shape = arrays["outcome"].shape
    if shape[-2:] != (lam.size, r.size):
        raise ValueError(f"outcome has shape {shape}, not (..., {lam.size}, {r.size})")
    for k in _FIELDS:
        if arrays[k].shape != shape:
            raise ValueError(f"{k} has shape {arrays[k].shape}, outcome {shape}")
    _check_codes(arrays)


def _check_codes(arrays: dict) -> None:
    """`ValueError` unless outcome and status hold known codes."""
    for k, codes in (("outcome", Outcome), ("status", Status)):
        if not np.isin(arrays[k], [int(c) for c in codes]).all():
            raise ValueError(f"{k} holds codes other than {[int(c) for c in codes]}")


def _check_chunk(arrays: dict, cells=None) -> None:
    """`ValueError` unless a stored chunk's arrays agree: a 1-D index of
    cells (`cells`, if given), a value of each field per cell, floats or
    integers as computed, known codes, and its lane-step counts."""
    index = arrays["index"]
    if index.ndim != 1 or index.dtype.kind not in "iu":
        raise ValueError(f"its index is not cells: {index.dtype} {index.shape}")
    if cells is not None and not np.array_equal(index, cells):
        raise ValueError("its cells are not those the store's order deals it")
    floats = ("max_rotation", "max_base_displacement", "uplift_time")
    for k in _FIELDS:
        x = arrays[k]
        if x.shape != index.shape or x.dtype.kind not in ("f" if k in floats else "iu"):
            raise ValueError(f"{k} is {x.dtype} {x.shape}, for {index.size} cells")
    _check_codes(arrays)
    _check_counts(arrays)


def _check_counts(arrays: dict) -> None:
    """`ValueError` unless the lane-step counts "useful" and "executed" are
    integers, 0 <= useful <= executed."""
    useful, executed = arrays["useful"], arrays["executed"]
    numbers = all(x.shape == () and x.dtype.kind in "iu" for x in (useful, executed))
    if not (numbers and 0 <= useful <= executed):
        raise ValueError(f"lane-step counts useful {useful}, executed {executed}")


def _member_label(c: Coordinates, index: int) -> str:
    """The parameters that vary along the leading axis of `c`, at `index`
    ("amplitude = 2 m/s"); "" if none is labelled."""
    parts = []
    for name, (dims, values, attrs) in c.coords.items():
        if len(dims) == 1 and dims[0] == c.dims[0] and name != "record":
            units = attrs.get("units", "")
            value = f"{np.asarray(values)[index]:g} {'' if units == '1' else units}"
            parts.append(f"{name} = {value.strip()}")
    return ", ".join(parts)


def _leaf_digest(module) -> str:
    """A short fingerprint of a module's array leaves (to match a store)."""
    h = hashlib.sha256()
    for x in jax.tree_util.tree_leaves(module):
        h.update(np.ascontiguousarray(np.asarray(x, dtype=float)).tobytes())
    return h.hexdigest()[:16]


def _cells_of(module, shape, index):
    """Every leaf broadcast to `shape`, flattened and taken at `index` (1-D)."""
    return jax.tree_util.tree_map(
        lambda x: np.broadcast_to(np.asarray(x), shape).reshape(-1)[index], module
    )


# Memory a map holds per cell on the host: inputs, indices, results and the
# chunks' carries (measured: about 0.5 kB a cell at 2,440 to 100,000 cells).
_BYTES_PER_CELL = 1024


def _check_fits_in_memory(n: int) -> None:
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


class _Grid:
    """The cells of a map and their pilots.

    Cells run over (base batch, motion batch, slenderness, size) in C order;
    one pilot per (base, motion, slenderness) runs the shared translation phase
    (see `_map_chunk`). `inputs` gives the per-cell arrays of chosen cells."""

    def __init__(self, lam, r, base, motion):
        self.lam, self.r, self.base, self.motion = lam, r, base, motion
        self.motion_shape = motion.batch_shape
        self.motion_names = motion.names() if self.motion_shape else None
        # A suite of records: the cells index into it (one copy of the samples).
        self.suite = motion.shared_by_cells and self.motion_shape != ()
        # One motion (a single record) shared by every cell.
        self.one_motion = motion.shared_by_cells and not self.suite
        self.base_shape = broadcast_batch_shape(base)
        self.shape = self.base_shape + self.motion_shape + (lam.size, r.size)
        self.n = int(np.prod(self.shape))
        n_base, n_motion = (
            int(np.prod(self.base_shape)),
            int(np.prod(self.motion_shape)),
        )
        ib, im, il, ir = np.unravel_index(
            np.arange(self.n), (n_base, n_motion, lam.size, r.size)
        )
        self.pilots = n_base * n_motion * lam.size
        self.pilot_of_cell = (ib * n_motion + im) * lam.size + il
        pb, pm, pl = np.unravel_index(
            np.arange(self.pilots), (n_base, n_motion, lam.size)
        )
        self.pilot_inputs = self.inputs(pb, pm, pl, np.zeros_like(pl))
        self.cell_inputs = self.inputs(ib, im, il, ir)

    def inputs(self, ib, im, il, ir):
        """(slenderness, size, base, motion) of the cells (ib, im, il, ir) (1-D
        index arrays); the motion is None for one motion of every cell, the
        index into the suite for a suite of records."""
        if self.one_motion:
            motion = None
        elif self.suite:
            motion = im
        else:
            motion = _cells_of(self.motion, self.motion_shape, im)
        return (
            self.lam[il],
            self.r[ir],
            _cells_of(self.base, self.base_shape, ib),
            motion,
        )

    def blank_carries(self):
        """Zero carries of every pilot (the `shared` input of the pilot pass)."""
        first = lambda tree: jax.tree_util.tree_map(lambda x: x[0], tree)  # noqa: E731
        _, _, base, motion = self.pilot_inputs
        if self.one_motion:
            motion = self.motion
        elif self.suite:
            motion = self.motion.select(0).unlabeled()
        else:
            motion = first(motion)
        proto = jax.eval_shape(
            initial_carry, Block(self.lam[0], self.r[0]), first(base), motion
        )
        return jax.tree_util.tree_map(
            lambda s: np.zeros((self.pilots,) + s.shape, s.dtype), proto
        )

    def store_key(self, duration, chunk, opts) -> str:
        """What identifies the map's chunks in a store."""
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
                options=_leaf_digest(opts),
                solver=repr(opts.solver),
                max_segments=opts.max_segments,
                layout="cells dealt by start",  # chunks list their cells
            )
        )


def _numpy(tree):
    """The pytree with its JAX arrays as NumPy arrays (picklable: a task's)."""
    return jax.tree_util.tree_map(
        lambda x: np.asarray(x) if isinstance(x, jax.Array) else x, tree
    )


def _device_args(task, device) -> tuple:
    """The arguments of `_map_chunk` but its loop, from a task
    (`_ChunkRunner.task`), on `device`."""
    *head, opts, count, pilot = task
    opts = jax.tree_util.tree_map(
        lambda x: jax.device_put(x, device) if isinstance(x, np.ndarray) else x, opts
    )
    return (
        *jax.device_put(tuple(head), device),
        opts,
        *jax.device_put((count, pilot), device),
    )


def _compute_chunk(task, device=None) -> dict:
    """One chunk of a map: the task `behavior_map` gives an executor.

    `task` holds the NumPy arguments of `_map_chunk` but its loop
    (`_ChunkRunner.task`); they go to `device` (default: the first local
    device). Returns NumPy arrays: for a chunk of cells its `_FIELDS`, for a
    chunk of pilots the leaves of their carries ("carries", a list), each for
    the chunk's cells only (not its padding); and the lane-steps executed and
    those that advanced an analysis ("executed", "useful").
    """
    device = device or jax.local_devices()[0]
    args = _device_args(task, device)
    leaves, treedef = jax.tree_util.tree_flatten(args)
    program = _chunk_program(treedef, leaves, _layout.loop_for(device.platform))
    fields, carries, executed, useful = jax.device_get(program(*leaves))
    count, pilot = int(task[-2]), bool(task[-1])
    if pilot:
        out = {"carries": [x[:count] for x in carries]}
    else:
        out = {f: np.asarray(x)[:count] for f, x in zip(_FIELDS, fields)}
    return out | {"executed": np.asarray(executed), "useful": np.asarray(useful)}


# The chunk loops of this process (see `_chunk_program`), each made once: a
# map in another thread that needs a loop being made waits for it.
_PROGRAMS: dict = {}
_PROGRAM_LOCKS: dict = {}
_PROGRAMS_LOCK = threading.Lock()
# Tracing and lowering are Python, under the GIL: maps in threads take turns,
# and one traces while another compiles (XLA compiles without the GIL).
_TRACING = threading.Lock()


def _chunk_program(treedef, leaves, loop: _layout.Loop):
    """`_map_chunk` for arguments of the structure `treedef` (static fields
    included) and the shapes and device of `leaves` (jax Arrays), as `loop`,
    compiled: a function of the leaves that returns the
    responses' `_FIELDS`, the carries' leaves, and the lane-steps executed and
    useful.

    Made once per process and device. With jaxrock's cache folder
    (`_cache.program_folder`) and one local device, the compiled program is
    kept there, and a later process loads it instead of tracing, lowering and
    compiling again. A structure that names code outside jaxrock and its
    dependencies (a user's isolator class) is compiled in every process.
    """
    specs = tuple(
        jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding) for x in leaves
    )
    key = (treedef, specs, loop)
    with _PROGRAMS_LOCK:
        lock = _PROGRAM_LOCKS.setdefault(key, threading.Lock())
    with lock:
        if key not in _PROGRAMS:
            _PROGRAMS[key] = _make_program(treedef, specs, loop)
        return _PROGRAMS[key]


def _make_program(treedef, specs, loop: _layout.Loop):
    """`_chunk_program`'s function, compiled here or loaded from the folder."""

    args = jax.tree_util.tree_unflatten(treedef, specs)
    options = _compiler_options(base=args[2], motion=args[3])

    def map_chunk(*leaves):
        args = jax.tree_util.tree_unflatten(treedef, leaves)
        responses, carries, executed, useful = _map_chunk(*args, loop)
        fields = tuple(getattr(responses, f) for f in _FIELDS)
        return fields, tuple(jax.tree_util.tree_leaves(carries)), executed, useful

    traced = jax.jit(map_chunk, compiler_options=options)

    def lower():
        with _TRACING:
            return traced.lower(*specs)

    static = _cache.static_key(treedef)
    shapes = [(s.shape, str(s.dtype)) for s in specs]
    key = json.dumps([static, shapes, list(loop), options])
    if static is None or len(jax.local_devices()) > 1:
        key = None  # not kept
    return _cache.compiled("map_chunk", key, lower)


def _compiler_options(base: AbstractIsolator, motion: AbstractGroundMotion) -> dict:
    """XLA's options for a chunk loop on `base` under `motion`.

    On the CPU, a loop under a closed-form motion on a base without a
    hysteretic state compiles with XLA's loop emitters instead of its fusion
    emitters: it compiles faster and runs about as fast, while records' reads
    of their samples and a friction pendulum's z run faster with the fusion
    emitters (the docs' performance page, "Choices in the code").
    (XLA releases without that option, jaxlib 0.11 on, keep their default.)
    """
    if jax.default_backend() != "cpu":
        return {}
    if motion.sample_count > 0 or base.hysteretic_state:
        return {}
    options = {"xla_cpu_use_fusion_emitters": False}
    return options if compiler_accepts(options) else {}


class _ChunkRunner:
    """Runs chunks of cells through `_map_chunk` (`_compute_chunk`), on the
    local devices or as the tasks of an executor.

    A chunk's cells are padded to `padded` (the last cell repeated, never
    analysed) so that maps of other sizes reuse a handful of compiles. Without
    an executor, chunks go round-robin to the local devices (GPUs, or several
    CPU devices with XLA_FLAGS=--xla_force_host_platform_device_count=N), from
    one thread per CPU core: XLA releases the GIL, so chunks run at once.
    """

    def __init__(self, grid: _Grid, duration, opts, padded: int, executor=None):
        self.grid, self.padded, self.executor = grid, padded, executor
        self.motion, self.duration, self.opts = _numpy(
            (grid.motion.unlabeled(), duration, opts)
        )
        self.one_base = _numpy(grid.base) if grid.base_shape == () else None
        self.devices = jax.local_devices()
        # A thread per CPU core, or per accelerator (each runs its chunks in turn).
        cpu = self.devices[0].platform == "cpu"
        self.threads = len(self.devices)
        if cpu:
            self.threads = max(self.threads, os.cpu_count() or 1)

    def task(self, index, inputs, shared, pilot) -> tuple:
        """The arguments of `_map_chunk` but its loop, as NumPy, for the
        cells `index` of `inputs` and `shared`: a task of `_compute_chunk`."""
        count = index.size
        take = np.pad(index, (0, self.padded - count), mode="edge")

        def part(tree):
            return jax.tree_util.tree_map(lambda x: np.asarray(x)[take], tree)

        lam_k, r_k, base_k, motion_k = inputs
        suite_index = part(motion_k) if self.grid.suite else None
        motion = self.motion if self.grid.motion.shared_by_cells else part(motion_k)
        return (
            part(lam_k),
            part(r_k),
            part(base_k),
            motion,
            suite_index,
            part(shared),
            self.one_base,
            self.duration,
            self.opts,
            np.asarray(count),
            np.asarray(pilot),
        )

    def device(self, k):
        """Chunk k's local device (round-robin)."""
        return self.devices[k % len(self.devices)]

    def run(self, jobs, inputs, shared, pilot, done=None, bar=None) -> dict:
        """The chunks `jobs` ({k: its cells}) of pass 1 (`pilot`) or 2 of the
        cells `inputs` and `shared`: {k: `_compute_chunk`'s result}, and
        done(k, result) as each ends; the progress bar `bar` counts them.

        On the executor, if any (`run_tasks`); else round-robin over the local
        devices from one thread per CPU core (the first chunk of a device
        compiles its loop, the others wait for it).
        """

        def task(k):
            return self.task(jobs[k], inputs, shared, pilot)

        if self.executor is not None:
            what = "pilot chunk" if pilot else "chunk"
            tasks = {k: task(k) for k in jobs}
            return run_tasks(self.executor, _compute_chunk, tasks, what, done, bar)

        def compute(k):
            out = _compute_chunk(task(k), self.device(k))
            if done is not None:
                done(k, out)
            return out

        out = {}
        with ThreadPoolExecutor(self.threads) as pool:
            for k, result in zip(jobs, pool.map(compute, jobs)):
                out[k] = result
                if bar is not None:
                    bar.update(1)
        return out


def _run_pilots(runner: _ChunkRunner, grid: _Grid, chunk: int):
    """Pass 1: the pilots, from t = 0 to where their cells part ways, `chunk`
    at a time. Returns every cell's start (its pilot's carry) and the pilots'
    useful and executed lane-steps."""
    blank = grid.blank_carries()
    pilots = range(0, grid.pilots, chunk)
    pilots = {
        k: np.arange(i, min(i + chunk, grid.pilots)) for k, i in enumerate(pilots)
    }
    done = runner.run(pilots, grid.pilot_inputs, blank, True)
    leaves = zip(*(done[k]["carries"] for k in range(len(done))))
    carries = jax.tree_util.tree_unflatten(
        jax.tree_util.tree_structure(blank), map(np.concatenate, leaves)
    )
    starts = jax.tree_util.tree_map(lambda x: x[grid.pilot_of_cell], carries)
    useful = sum(int(d["useful"]) for d in done.values())
    executed = sum(int(d["executed"]) for d in done.values())
    return starts, useful, executed


def behavior_map(
    slenderness,
    size,
    base: AbstractIsolator,
    motion: AbstractGroundMotion,
    *,
    duration: float | None = None,
    rtol: float = RTOL,
    atol: float = ATOL,
    chunk_size: int | str | None = "auto",
    progress: bool | None = None,
    max_segments: int = MAX_SEGMENTS,
    max_steps: int | None = None,
    rest_tolerance: float = REST_TOLERANCE,
    solver=None,
    store: str | os.PathLike | None = None,
    executor: Executor | None = None,
) -> "BehaviorMap":
    """Classify every block of the grid `slenderness` x `size` (1-D arrays).

    Every cell is the exact analysis of `simulate`; on a fixed base the free
    rocking after the excitation is finished in closed form (`_free.py`: the
    same apexes, impacts, rest rule and segments, without steps; `steps`
    counts the integrated part). The parameters of `base` and
    of an `MPPulse` may carry batch axes (an ensemble of isolators or of pulses,
    e.g. `LinearIsolator(period=jnp.array([1.5, 2.0, 2.5]), ...)`): the result
    then has shape base batch + pulse batch + (n_slenderness, n_size).
    Cells run `chunk_size` at a time (`None`: all at once; "auto", the
    default: 610 with a store or an executor, else as few chunks as keep the
    devices busy: on a CPU a multiple of its cores, of at most 8,192 cells
    each; on a GPU one chunk per GPU of up to 1,048,576 cells) through one
    compiled loop on vmapped lanes (64 on a CPU, 65,536 on a GPU); each
    iteration advances every lane by one solver step, and a lane that
    finishes takes the chunk's next cell (the "flat loop", `_flat.py`). The
    pure-translation phase before uplift runs once per base, motion and
    slenderness (see `_map_chunk`), and the cells, ordered by where that
    leaves them, are dealt to the chunks in turn (equal work per chunk).
    Chunks run one thread per CPU core, or per GPU.
    `progress` shows a tqdm bar (default: when there is more than one chunk).
    New grids, pulses or isolator parameters reuse the compile.

    `store=DIR` writes each finished chunk to DIR (resumable: a rerun computes
    only the missing chunks, dealt the cells as the first run dealt them; a
    damaged chunk is computed again, with a `RuntimeWarning` naming it).

    `executor`, a `concurrent.futures.Executor` (a `ProcessPoolExecutor`, a
    Dask cluster's `Client.get_executor()`, an `mpi4py.futures.MPIPoolExecutor`),
    runs every chunk as one task instead of the local threads: the task
    (`_compute_chunk`) takes and returns NumPy arrays. The pilots (the shared
    phase, one chunk per `chunk_size` of them) run as tasks first, then the
    chunks of cells; each result goes to the store as it arrives, and a task
    that fails (after the executor's own retries) raises `RuntimeError` naming
    its chunk. The map is the same to the bit as without an executor.
    """
    check_base_and_motion(base, motion)
    check_executor(executor)
    lam, r = grid_axis("slenderness", slenderness), grid_axis("size", size)
    Block(lam, 1.0), Block(1.0, r)  # the ranges of each axis
    if duration is None:
        duration = float(np.max(np.asarray(motion.end_time))) + 5.0
    duration = one_real_number("duration", duration, "finite and > 0 (s)")
    positive("duration", duration)
    chunk_size = _layout.chunk_size(
        chunk_size, store is not None or executor is not None
    )
    opts = SolverOptions.for_motion(
        motion, rtol, atol, max_steps, max_segments, rest_tolerance, solver
    )
    shape = broadcast_batch_shape(base) + motion.batch_shape + (lam.size, r.size)
    _check_fits_in_memory(int(np.prod(shape)))
    grid = _Grid(lam, r, base, motion)
    chunk, padded, chunks = _layout.chunk_plan(grid.n, chunk_size)
    if progress is None:
        progress = chunks > 1
    duration = as_float(duration)
    runner = _ChunkRunner(grid, duration, opts, padded, executor)
    if store is not None:
        key = grid.store_key(duration, chunk, opts)
        store = ChunkStore(store, key, _FIELDS + ("index", "executed", "useful"))

    t = time.perf_counter()
    # From an earlier run: its chunks, and the pilots' counts once all are there.
    results, counts = ({}, None) if store is None else _stored(store, grid, chunks)
    bar = _progress_bar(progress, chunks, len(results), type(base).__name__)
    if counts is None:
        starts, useful, executed = _run_pilots(runner, grid, chunk)
        if store is not None:  # for `lane_efficiency` of a map read back whole
            store.write("pilots", dict(useful=useful, executed=executed))
        results |= _run_cells(runner, grid, starts, chunks, results, store, bar)
    else:  # every chunk from the store
        useful, executed = counts
    if bar is not None:
        bar.close()
    seconds = time.perf_counter() - t
    results = [results[k] for k in range(chunks)]
    return _assemble(grid, results, seconds, useful, executed)


def _stored(store: ChunkStore, grid: _Grid, chunks: int):
    """What an earlier run left in `store`: {k: chunk k} of the chunks whose
    arrays agree (`_check_chunk`; with the order stored, chunk k holds the
    cells it deals chunk k), and the pilots' lane-step counts (useful,
    executed) if every chunk, the order and the counts are there, else None
    (the pilots run again)."""
    order = store.order(grid.n)

    def check(k, arrays):
        _check_chunk(arrays, None if order is None else order[k::chunks])

    results = store.chunks(chunks, check)
    if len(results) < chunks or order is None:
        return results, None
    pilots = store.read("pilots", ("useful", "executed"), _check_counts)
    if pilots is None:
        return results, None
    return results, (int(pilots["useful"]), int(pilots["executed"]))


def _progress_bar(progress: bool, chunks: int, done: int, base: str):
    """A tqdm bar over the chunks (`done` of them from a store) of a map on
    `base` (the name it shows: maps in threads each have a bar), or None."""
    if not progress:
        return None
    from tqdm.auto import tqdm

    desc = f"behavior map, {base}"
    return tqdm(total=chunks, initial=done, desc=desc, unit="chunk")


def _run_cells(runner: _ChunkRunner, grid: _Grid, starts, chunks, done, store, bar):
    """Pass 2: the cells from their starts (`_run_pilots`), dealt to `chunks`
    chunks, but those `done` (from a store); each finished chunk goes to the
    store. Returns the new chunks' results."""
    # Cells by start time (the most work first), dealt to the chunks in turn:
    # chunks of equal work, and short analyses fill each one's tail. A store
    # keeps its first run's order: a rerun whose pilots differ in their last
    # bits (other hardware) deals the same chunks; one whose order was lost
    # deals them anew, and a stored chunk dealt otherwise is computed again.
    order = np.argsort(starts.t, kind="stable")
    if store is not None:
        order = store.dealt(order)
        same = {k: np.array_equal(done[k]["index"], order[k::chunks]) for k in done}
        for k in (k for k in done if not same[k]):
            store.damaged(store.path(k), "its cells are not those its order deals it")
        done = {k: c for k, c in done.items() if same[k]}
    cells = {k: order[k::chunks] for k in range(chunks) if k not in done}

    def finished(k, out):
        """Chunk k: its cells ("index") join its results."""
        out["index"] = cells[k]
        if store is not None:
            store.write(k, out)

    return runner.run(cells, grid.cell_inputs, starts, False, finished, bar)


def _assemble(grid: _Grid, results, seconds, useful, executed) -> BehaviorMap:
    """The map from its chunks' results, in grid order."""
    index = np.concatenate([c["index"] for c in results])
    if not np.array_equal(np.sort(index), np.arange(grid.n)):
        raise RuntimeError(
            "the chunks do not hold every cell exactly once (a store whose "
            "chunks were dealt differently?)"
        )
    cell_order = np.argsort(index)
    fields = {
        f: np.concatenate([c[f] for c in results])[cell_order].reshape(grid.shape)
        for f in _FIELDS
    }
    useful += sum(int(c["useful"]) for c in results)
    executed += sum(int(c["executed"]) for c in results)
    return BehaviorMap(
        slenderness=grid.lam,
        size=grid.r,
        **fields,
        base=grid.base.describe(),
        motion=grid.motion.describe(),
        seconds=seconds,
        lane_efficiency=useful / max(executed, 1),
        motion_names=grid.motion_names,
        coordinates=coordinates(grid.base, grid.motion),
    )
