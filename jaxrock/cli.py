"""Command line: `jaxrock map` (behavior maps) and `jaxrock simulate` (one block)."""

import argparse
import os
import sys


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
    if n < 1 or not (start > 0 and stop >= start):
        raise argparse.ArgumentTypeError(
            f"need 0 < START <= STOP and N >= 1, got {text!r}"
        )
    return np.linspace(start, stop, n)


def _parser():
    p = argparse.ArgumentParser(prog="jaxrock", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    def base_options(q):
        q.add_argument(
            "--base",
            choices=["fixed", "linear", "fps"],
            default="linear",
            help="base to analyse (default linear; `map` and `spectrum` also draw "
            "the fixed base beside it, `map` unless --no-compare)",
        )
        q.add_argument("--period", type=float, default=2.0, help="T_s (s)")
        q.add_argument("--damping", type=float, default=0.35, help="xi")
        q.add_argument("--friction", type=float, default=0.11, help="mu (fps)")
        q.add_argument("--radius", type=float, default=2.24, help="R (m) (fps)")
        q.add_argument("--mass-ratio", type=float, default=0.5, help="m / m_b")
        q.add_argument("--out", default=None, help="output PNG")

    def one_block(q):
        q.add_argument("--slenderness", type=float, default=4.0, help="lambda = h/b")
        q.add_argument("--size", type=float, default=1.0, help="r (m)")

    def common(q):
        base_options(q)
        g = q.add_mutually_exclusive_group()
        g.add_argument(
            "--pulse",
            default="San Fernando PCD/SN",
            help="a Table 3.1 pulse name (default: %(default)s)",
        )
        g.add_argument("--record", help="a PEER NGA .AT2 file instead of a pulse")
        q.add_argument(
            "--scale",
            type=float,
            default=1.0,
            help="amplitude factor of the motion (default 1)",
        )

    m = sub.add_parser("map", help="behavior map over slenderness and size")
    common(m)
    m.add_argument(
        "--slenderness",
        type=_range,
        default="1.0:7.0:61",
        help="START:STOP:N (default 1.0:7.0:61)",
    )
    m.add_argument(
        "--size",
        type=_range,
        default="0.1:4.0:40",
        help="START:STOP:N in m (default 0.1:4.0:40)",
    )
    m.add_argument(
        "--no-compare",
        action="store_true",
        help="only the chosen base, not the fixed base beside it",
    )
    m.add_argument("--chunk-size", type=int, default=610)
    m.add_argument(
        "--store",
        default=None,
        help="folder for finished chunks: an interrupted map resumes",
    )
    f = sub.add_parser("fragility", help="fragility curves over a scaled pulse")
    common(f)
    one_block(f)
    f.add_argument(
        "--scales",
        type=_range,
        default="0.1:2.0:40",
        help="amplitude scales START:STOP:N (default 0.1:2.0:40)",
    )
    f.add_argument("--measure", choices=["pga", "pgv", "pga_ratio"], default="pga")
    o = sub.add_parser("spectrum", help="overturning spectrum under one-sine pulses")
    base_options(o)
    one_block(o)
    o.add_argument(
        "--frequency-ratio",
        type=_range,
        default="0.5:8:16",
        help="omega_p / p, START:STOP:N (default 0.5:8:16)",
    )
    o.add_argument(
        "--amplitude-ratio",
        type=_range,
        default="1:8:36",
        help="a_p / (g tan alpha), START:STOP:N (default 1:8:36)",
    )
    s = sub.add_parser("simulate", help="one block: a one-line result and a plot")
    common(s)
    one_block(s)
    return p


def _base(a):
    import jaxrock as jr

    if a.base == "fixed":
        return jr.FixedBase()
    if a.base == "linear":
        return jr.LinearIsolator(a.period, a.damping, a.mass_ratio)
    return jr.FrictionPendulum(a.friction, a.radius, a.mass_ratio)


def _inputs(a):
    import jaxrock as jr

    if a.record:
        if not os.path.isfile(a.record):
            raise ValueError(f"no such file: {a.record}")
        rec = jr.io.read_at2(a.record)
        motion = jr.Record(rec.samples * a.scale, rec.dt)
        name = os.path.basename(a.record)
    else:
        motion = jr.near_fault_pulse(a.pulse, scale=a.scale)
        name = a.pulse
    return motion, _base(a), name


def main(argv=None) -> int:
    a = _parser().parse_args(argv)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import jaxrock as jr
        from jaxrock import plot

        if a.command == "spectrum":
            block = jr.Block(a.slenderness, a.size)
            bases = [jr.FixedBase()] + ([] if a.base == "fixed" else [_base(a)])
            spectra = [
                jr.overturning_spectrum(
                    block, b, a.frequency_ratio, a.amplitude_ratio, progress=False
                )
                for b in bases
            ]
            for s_ in spectra:
                print(
                    f"{s_.base}: minimum a_p / (g tan alpha) = "
                    + " ".join(f"{m:.3g}" for m in s_.minimum)
                )
            out = a.out or "spectrum.png"
            plot.overturning_spectrum(spectra).figure.savefig(out, dpi=120)
            print(f"wrote {out}")
            return 0
        motion, base, name = _inputs(a)
        if a.command == "simulate":
            r = jr.simulate(jr.Block(a.slenderness, a.size), base, motion, history=True)
            print(r.summary())
            out = a.out or "response.png"
            plot.response(r).savefig(out, dpi=120)
            print(f"wrote {out}")
            return 0
        if a.command == "fragility":
            if a.record:
                raise ValueError("fragility takes a pulse (--pulse), not a record")
            p = jr.near_fault_pulse(a.pulse, scale=a.scale)
            motions = jr.MPPulse(a.scales * p.amplitude, p.frequency, p.gamma, p.phase)
            frag = jr.fragility(
                a.slenderness, a.size, base, motions, measure=a.measure, progress=False
            )
            print(
                f"{a.scales.size} analyses: {int(frag.rocked.sum())} rocked, "
                f"{int(frag.overturned.sum())} overturned; median {a.measure} "
                f"to overturn {frag.median_overturning:.4g} "
                f"(beta {frag.beta_overturning:.3g})"
            )
            out = a.out or "fragility.png"
            ax = plot.fragility(
                frag,
                title=f"{name}, lambda = {a.slenderness:g}, "
                f"r = {a.size:g} m, {type(base).__name__}",
            )
            ax.figure.savefig(out, dpi=120)
            print(f"wrote {out}")
            return 0
        bases = [base] if a.no_compare or a.base == "fixed" else [jr.FixedBase(), base]
        maps = []
        for b in bases:
            store = None if a.store is None else os.path.join(a.store, type(b).__name__)
            bm = jr.behavior_map(
                a.slenderness, a.size, b, motion, chunk_size=a.chunk_size, store=store
            )
            print(bm.summary().replace(bm.motion, name))
            maps.append(bm)
        out = a.out or "behavior_map.png"
        stem = os.path.splitext(out)[0]
        for b, bm in zip(bases, maps):
            kind = type(b).__name__
            bm.save(f"{stem}_{kind}.npz")
        titles = [f"{name}\n{bm.base}" for bm in maps]
        plot.compare_maps(maps, titles).savefig(out, dpi=120)
        print(f"wrote {out} and {stem}_*.npz")
        return 0
    except (ValueError, TypeError, OSError) as err:
        print(f"jaxrock: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
