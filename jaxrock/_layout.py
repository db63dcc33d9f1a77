"""How a map's cells are laid out on a device: the lanes of one compiled loop,
and the chunks of cells that go through it.

A chunk's loop advances `lane_width` analyses at once (its lanes), and a lane
that finishes takes the chunk's next cell. On a CPU a few dozen lanes fill a
core's vector units; a GPU needs tens of thousands of analyses in flight to
fill its multiprocessors, and runs a whole map in one chunk where a CPU splits
it over its cores. Everything here is decided once, before any loop runs,
from the platform of the devices that run the map.
"""

import os
from typing import NamedTuple

import jax

from ._misc import is_count

# Lanes of one compiled loop on a CPU: enough to fill a core's vector units,
# few enough that lanes seldom wait for each other (the docs' performance
# page, "Choices in the code", has the timings of 32, 64 and 128).
CPU_LANE_WIDTH = 64
# Lanes of one compiled loop on an accelerator (a GPU): each iteration of the
# loop is a sequence of kernel launches whose cost grows slowly with the
# number of lanes, so the lanes are as many as keep the chunk's tail short:
# a million analyses under a record keep 131,072 lanes 91% busy, and 262,144
# lanes 68% (benchmarks/device.py --lanes measures the choice).
ACCELERATOR_LANE_WIDTH = 131072

# Cells a chunk holds by default when chunks are units of work for a store or
# an executor (`chunk_size`).
CHUNK_SIZE = 610
# The most cells of a chunk with chunk_size="auto": on a CPU, chunks enough to
# keep every core busy; on an accelerator, a million-cell map in one chunk
# (its device memory: about 1 kB a cell).
MAX_CHUNK_SIZE = 8192
ACCELERATOR_MAX_CHUNK_SIZE = 1 << 20
# The smallest chunk shape: small maps share one compile.
SMALLEST_CHUNK = 64
# The most cells of a map that runs on the host's CPU by default where JAX's
# devices are accelerators (`map_devices`): on an H100 a map of 16,384 cells
# under a record runs about as fast as on two CPU cores, a smaller one slower.
HOST_MAP_CELLS = 16384


class Loop(NamedTuple):
    """The shape of a chunk's compiled loop on a device.

    Attributes:
        lanes: the analyses the loop advances at once.
        one_event_batch: whether the lanes that end a step (an event, a
            segment's end) have their events located all together, each lane
            kept or replaced as it ends (an accelerator: a pass of a loop is a
            round trip to the host, and thousands of lanes end in a step), or
            gathered in batches of a few lanes (a CPU: no lane that moves on
            pays for a root find).
    """

    lanes: int
    one_event_batch: bool


def map_devices(cells: int) -> list[jax.Device]:
    """The devices that run a map of `cells` cells by default: the local
    devices, but the host's CPU where they are accelerators and the map has at
    most `HOST_MAP_CELLS` cells.

    A GPU compiles a map's loop in 10-40 s, and a map of a few thousand cells
    starts all its analyses at once in the GPU's lanes, which then wait for
    the longest: it runs slower there than on two CPU cores (the docs'
    performance page, "On a GPU"). Without a CPU backend (`JAX_PLATFORMS`
    names none), the local devices."""
    host = host_devices() if cells <= HOST_MAP_CELLS else None
    return jax.local_devices() if host is None else host


def host_devices() -> list[jax.Device] | None:
    """The host's CPU devices where JAX's local devices are accelerators;
    None where they are CPUs, or where there is no CPU backend
    (`JAX_PLATFORMS` names none). One analysis (`jaxrock simulate`) and
    small maps run there: their compile and their sequence of events cost
    less on a CPU."""
    if jax.local_devices()[0].platform == "cpu":
        return None
    try:
        return jax.local_devices(backend="cpu")
    except RuntimeError:
        return None


def loop_for(platform: str) -> Loop:
    """The loop of a chunk on a device of `platform` ("cpu", "gpu", ...)."""
    if platform == "cpu":
        return Loop(CPU_LANE_WIDTH, one_event_batch=False)
    return Loop(ACCELERATOR_LANE_WIDTH, one_event_batch=True)


def lane_width(platform: str) -> int:
    """The lanes of a chunk's compiled loop on a device of `platform`."""
    return loop_for(platform).lanes


def chunk_size(value, units: bool) -> int | str | None:
    """`chunk_size` as an int >= 1, None (all at once) or "auto"; "auto" is
    `CHUNK_SIZE` when chunks are `units` of work (for a store or an executor),
    else left to `chunk_plan` (`ValueError` for anything else)."""
    if isinstance(value, str) and value == "auto":
        return CHUNK_SIZE if units else value
    if value is None:
        return None
    if not is_count(value) or value < 1:
        raise ValueError(
            f"`chunk_size` must be an integer >= 1, None or 'auto', got {value!r}"
        )
    return int(value)


def chunk_plan(n: int, chunk_size, devices=None) -> tuple[int, int, int]:
    """(cells a chunk, its padded size, chunks) of a map of n cells on
    `devices` (default: the local devices).

    Chunks are padded to a power of two of at least `SMALLEST_CHUNK` cells:
    maps of other sizes reuse a handful of compiles (padding costs nothing but
    idle lanes; a compile costs seconds). A chunk of at least a lane width is
    padded to a whole number of lane widths: XLA's vectorized loops over its
    cells then leave no remainder, which they would compute with other
    roundings, and a cell's position in its chunk changes none of its bits.

    `chunk_size="auto"`: as few chunks as keep the devices (on a CPU, its
    cores) busy, a multiple of their number (none idles at the end), of at
    most `MAX_CHUNK_SIZE` cells on a CPU and `ACCELERATOR_MAX_CHUNK_SIZE` on
    an accelerator; a map of up to a lane width is one chunk. Few, large
    chunks lose little to their tails: a chunk lasts as long as its longest
    analysis, which under a suite of records is 10-15 times the mean."""
    devices = jax.local_devices() if devices is None else devices
    cpu = devices[0].platform == "cpu"
    width = lane_width(devices[0].platform)
    if isinstance(chunk_size, str):  # "auto"
        slots = max(len(devices), os.cpu_count() or 1) if cpu else len(devices)
        largest = MAX_CHUNK_SIZE if cpu else ACCELERATOR_MAX_CHUNK_SIZE
        chunks = 1 if n <= width else slots * -(-n // (slots * largest))
        chunk = -(-n // chunks)
        return chunk, _padded(chunk), chunks
    chunk = n if chunk_size is None else min(chunk_size, n)
    padded = _padded(chunk)
    if chunk_size is not None:
        whole = min(chunk_size, width)
        padded = min(padded, -(-chunk_size // whole) * whole)
    return chunk, padded, -(-n // chunk)


def _padded(chunk: int) -> int:
    """The power of two, at least `SMALLEST_CHUNK`, that holds `chunk` cells."""
    return max(1 << (chunk - 1).bit_length(), SMALLEST_CHUNK)
