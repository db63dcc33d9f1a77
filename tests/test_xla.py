"""XLA's option that compiles a while loop as one kernel (`jaxrock._xla`)."""

import contextlib
import os
import re
import warnings

import jax
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _chunk, _programs, _xla
from jaxrock._scene import MotionLayout


def _op_names(text: str, pattern: str) -> list[str]:
    """The op_names of the instructions of an HLO text that match `pattern`."""
    return [
        re.search(r'op_name="([^"]+)"', line).group(1)
        for line in text.splitlines()
        if re.search(pattern, line) and "op_name=" in line
    ]


def test_the_option_is_in_effect_in_this_process():
    assert f"{_xla.OPTION}=" in os.environ["XLA_FLAGS"]


def test_the_step_loop_of_a_record_map_is_one_kernel():
    """A map's chunk loop under a record (64 lanes, event batches of 8):
    its step loop is one kernel (XLA wraps the loop in a call that it emits
    whole), not a while loop run kernel by kernel. A scatter inside the step
    loop (writing a batch's lanes back) would keep it a while loop."""
    t = np.arange(0.0, 4.0, 0.01)
    record = jr.Record(3.0 * np.sin(2 * np.pi * t) * np.exp(-t), 0.01)
    before = set(_programs._PROGRAMS)
    jr.behavior_map([3.0, 5.0], [0.5, 1.5], jr.FixedBase(), record, progress=False)
    programs = [_programs._PROGRAMS[key] for key in set(_programs._PROGRAMS) - before]
    assert programs  # compiled (or loaded) here
    for program in programs:
        calls = _op_names(program.as_text(), r' call\(.*xla_cpu_small_call="true"')
        assert any(name.endswith(f"/{_chunk.STEP_LOOP}/while") for name in calls)


@pytest.fixture
def fresh(monkeypatch):
    """`compile_loops_whole` as before JAX starts, in a clean environment."""
    monkeypatch.setattr(jax._src.xla_bridge, "backends_are_initialized", lambda: False)
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    monkeypatch.delenv(_xla.ENVIRONMENT, raising=False)
    return monkeypatch


def test_the_option_is_added_to_the_users_flags(fresh):
    fresh.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    assert _xla.compile_loops_whole()
    flags = os.environ["XLA_FLAGS"].split()
    assert flags[0] == "--xla_force_host_platform_device_count=2"
    assert flags[1] == f"--xla_backend_extra_options={_xla.OPTION}={10**15}"


@pytest.mark.parametrize("setting", ["flattened", " Flattened "])
def test_flattened_adds_xlas_flattened_fusions(fresh, setting):
    fresh.setenv(_xla.ENVIRONMENT, setting)
    assert _xla.compile_loops_whole()
    assert os.environ["XLA_FLAGS"] == (
        f"--xla_backend_extra_options={_xla.OPTION}={10**15},{_xla.FLATTEN}"
    )


@pytest.mark.parametrize("setting", ["off", "0", "False"])
def test_the_option_is_left_out_when_turned_off(fresh, setting):
    fresh.setenv(_xla.ENVIRONMENT, setting)
    assert not _xla.compile_loops_whole()
    assert "XLA_FLAGS" not in os.environ


def test_the_users_backend_options_are_kept(fresh):
    own = f"--xla_backend_extra_options={_xla.OPTION}=0"
    fresh.setenv("XLA_FLAGS", own)
    assert _xla.compile_loops_whole()  # the user's value of the option
    assert os.environ["XLA_FLAGS"] == own
    fresh.setenv("XLA_FLAGS", "--xla_backend_extra_options=xla_cpu_ftz=1")
    assert not _xla.compile_loops_whole()
    assert os.environ["XLA_FLAGS"] == "--xla_backend_extra_options=xla_cpu_ftz=1"


def test_too_late_once_jax_has_computed(fresh):
    fresh.setattr(jax._src.xla_bridge, "backends_are_initialized", lambda: True)
    with pytest.warns(RuntimeWarning, match=f"import.* before JAX.*{_xla.ENVIRONMENT}"):
        assert not _xla.compile_loops_whole()
    assert "XLA_FLAGS" not in os.environ
    fresh.setenv(_xla.ENVIRONMENT, "off")  # the user's choice: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not _xla.compile_loops_whole()


def test_gpu_graphs_are_added_to_the_users_flags(fresh):
    fresh.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    assert _xla.control_flow_as_gpu_graphs()
    assert os.environ["XLA_FLAGS"].split() == [
        "--xla_force_host_platform_device_count=2",
        "--xla_gpu_enable_command_buffer=+WHILE,+CONDITIONAL",
    ]
    assert _xla.control_flow_as_gpu_graphs()  # once only
    assert os.environ["XLA_FLAGS"].count("command_buffer") == 1


def test_the_users_command_buffers_are_kept(fresh):
    own = "--xla_gpu_enable_command_buffer=-WHILE,-CONDITIONAL"
    fresh.setenv("XLA_FLAGS", own)
    assert not _xla.control_flow_as_gpu_graphs()
    assert os.environ["XLA_FLAGS"] == own


def test_gpu_graphs_too_late_once_jax_has_computed(fresh):
    fresh.setattr(jax._src.xla_bridge, "backends_are_initialized", lambda: True)
    assert not _xla.control_flow_as_gpu_graphs()
    assert "XLA_FLAGS" not in os.environ


def test_this_process_has_both_options():
    """`import jaxrock` (in conftest, before JAX computes) set both."""
    flags = os.environ["XLA_FLAGS"]
    assert _xla.GPU_GRAPHS in flags and _xla.OPTION in flags


def test_compiler_options_this_xla_does_not_take_are_left_out(monkeypatch):
    """XLA refuses a program with an option it does not know (jaxlib 0.11 has
    no xla_cpu_use_fusion_emitters): a pulse map's loop then compiles with
    XLA's defaults instead of failing."""
    assert _xla.compiler_accepts({})
    assert not _xla.compiler_accepts({"xla_cpu_no_such_option": False})
    pulse, base = jr.near_fault_pulse("San Fernando PCD/SN"), jr.FixedBase()
    layout = MotionLayout.of(pulse)
    fusion = {"xla_cpu_use_fusion_emitters": False}
    taken = fusion if _xla.compiler_accepts(fusion) else {}  # jaxlib 0.10, not 0.11
    assert _programs.compiler_options(base, layout) == taken
    monkeypatch.setattr(_programs, "compiler_accepts", lambda options, platform: True)
    assert _programs.compiler_options(base, layout) == fusion
    monkeypatch.setattr(_programs, "compiler_accepts", lambda options, platform: False)
    assert _programs.compiler_options(base, layout) == {}


def test_a_first_answer_compiles_at_level_0_and_gives_the_same_map(
    tmp_path, monkeypatch
):
    """Within `first_answer`, a fixed base's loop compiles at XLA's backend
    optimization level 0 (a friction pendulum's too where its chunk is small,
    else it keeps XLA's level):
    another program than the default, giving the same map (but for the last
    bits at level 0). `jaxrock map` compiles a small map so; a larger one
    keeps the default."""
    # The programs this test makes, whatever other tests of this process made.
    monkeypatch.setattr(_programs, "_PROGRAMS", {})
    pulse, layout = jr.near_fault_pulse("San Fernando PCD/SN"), MotionLayout.PER_CELL
    level = "xla_backend_optimization_level"
    assert level not in _programs.compiler_options(jr.FixedBase(), layout)
    assert _programs.compiler_options(jr.FixedBase(), layout, True)[level] == 0
    fps = jr.FrictionPendulum(0.11, 2.24, 0.5)
    assert level not in _programs.compiler_options(fps, layout, True)
    small, large = _programs.HYSTERETIC_LEVEL_0_CELLS, 2 * 8192
    assert _programs.compiler_options(fps, layout, True, None, small)[level] == 0
    assert level not in _programs.compiler_options(fps, layout, True, None, large)
    assert level not in _programs.compiler_options(fps, layout, False, None, small)

    lam, size = np.linspace(2.0, 6.0, 9), np.linspace(0.3, 3.0, 7)
    default = jr.behavior_map(lam, size, jr.FixedBase(), pulse, progress=False)
    before = set(_programs._PROGRAMS)
    with _programs.first_answer():
        quick = jr.behavior_map(lam, size, jr.FixedBase(), pulse, progress=False)
    new = set(_programs._PROGRAMS) - before
    assert new and all(f'"{level}": 0' in key[-1] for key in new)
    assert not _programs._FIRST_ANSWER
    np.testing.assert_array_equal(quick.outcome, default.outcome)
    np.testing.assert_array_equal(quick.impacts, default.impacts)
    np.testing.assert_allclose(quick.max_rotation, default.max_rotation, rtol=1e-9)

    # A friction pendulum's small map: level 0; the same map but for the
    # last bits.
    lam, size = np.linspace(2.0, 6.0, 3), np.array([0.5, 2.0])
    default = jr.behavior_map(lam, size, fps, pulse, progress=False)
    before = set(_programs._PROGRAMS)
    with _programs.first_answer():
        quick = jr.behavior_map(lam, size, fps, pulse, progress=False)
    (key,) = set(_programs._PROGRAMS) - before
    assert f'"{level}": 0' in key[-1]
    np.testing.assert_array_equal(quick.outcome, default.outcome)
    np.testing.assert_array_equal(quick.impacts, default.impacts)
    np.testing.assert_allclose(quick.max_rotation, default.max_rotation, rtol=1e-9)

    from jaxrock import cli

    entered, first_answer = [], _programs.first_answer

    @contextlib.contextmanager
    def spy():
        entered.append(_programs._FIRST_ANSWER)
        with first_answer():
            yield

    monkeypatch.setattr(_programs, "first_answer", spy)
    argv = ["map", "--base", "fixed", "--slenderness", "2:6:2", "--size", "0.5:2:2"]
    argv += ["--out", str(tmp_path / "map.png")]
    assert cli.main(argv) == 0 and entered == [False]
    monkeypatch.setattr(cli, "FIRST_ANSWER_CELLS", 3)  # the map has 4 cells
    assert cli.main(argv) == 0 and entered == [False]
