"""Reading ground motions from files (PEER NGA `.AT2`)."""

import os
import re

import numpy as np

from ._ground import Record
from ._misc import GRAVITY

_NEW_HEADER = re.compile(r"NPTS\s*=\s*(\d+)\s*,?\s*DT\s*=\s*([0-9.eE+-]+)", re.I)
_OLD_HEADER = re.compile(r"^\s*(\d+)\s+([0-9.eE+-]+)\s+NPTS\s*,?\s*DT", re.I)


def read_at2(path: str | os.PathLike) -> Record:
    """Read a PEER NGA `.AT2` accelerogram (units of g) as a `Record` in m/s^2.

    Accepts the header line `NPTS=  4172, DT=   .0100 SEC,` (with or without the
    commas) and the older `4164    0.0100    NPTS, DT`. The number of values must
    equal NPTS. Raises `ValueError` naming the file and the problem.
    """
    try:
        with open(path) as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise ValueError(f"cannot read AT2 file {str(path)!r}: {err}") from err
    for i, line in enumerate(lines[:10]):
        match = _NEW_HEADER.search(line) or _OLD_HEADER.search(line)
        if match:
            break
    else:
        raise ValueError(
            f"{str(path)!r} is not an AT2 file: no 'NPTS=..., DT=...' or "
            "'n dt NPTS, DT' line in its first 10 lines"
        )
    npts, dt = int(match.group(1)), float(match.group(2))
    try:
        values = np.array(" ".join(lines[i + 1 :]).split(), dtype=float)
    except ValueError as err:
        raise ValueError(f"{str(path)!r}: a value is not a number ({err})") from err
    if values.size != npts:
        raise ValueError(
            f"{str(path)!r}: header says NPTS = {npts} but the file holds "
            f"{values.size} values"
        )
    if not dt > 0:
        raise ValueError(f"{str(path)!r}: `dt` must be > 0, got {dt}")
    return Record(values * GRAVITY, dt)
