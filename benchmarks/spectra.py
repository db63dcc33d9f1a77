"""Response spectra and lognormal fits: the spectra of the FEMA P695
near-field pulse suite (28 components) at 200 periods, compiled and warm,
and 10,000 maximum-likelihood fits of overlapping binary outcomes. Writes
benchmarks/results/spectra.{json,md}.

    python benchmarks/spectra.py [--fits 10000] [--repeats 3]
"""

import argparse
import os
import time

import numpy as np

# Times include compiling: no compiled program from the cache folder.
os.environ.setdefault("JAXROCK_CACHE", "off")

from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr  # noqa: E402


def _best(run, repeats):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        run()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--fits", type=int, default=10000)
    p.add_argument("--repeats", type=int, default=3)
    a = p.parse_args(argv)
    suite = jr.Record.stack(jr.records.fema_p695("nearfield_pulse"))
    periods = np.geomspace(0.05, 5.0, 200)
    t = time.perf_counter()
    jr.response_spectrum(suite, periods)
    first = time.perf_counter() - t
    warm = _best(lambda: jr.response_spectrum(suite, periods), a.repeats)
    rows = [
        dict(
            task="spectra, 28 records x 200 periods",
            samples=int(suite.sample_count),
            first_s=round(first, 3),
            warm_s=round(warm, 3),
        )
    ]
    rng = np.random.default_rng(0)
    data = []
    for _ in range(a.fits):
        im = np.exp(rng.normal(0.0, 0.8, 40))
        failed = rng.random(40) < 1 / (1 + np.exp(-4 * np.log(im)))
        data.append((im, failed))
    t = time.perf_counter()
    jr.fit_lognormal(*data[0])
    first = time.perf_counter() - t
    t = time.perf_counter()
    for im, failed in data:
        jr.fit_lognormal(im, failed)
    rows.append(
        dict(
            task=f"{a.fits} fits of 40 binary outcomes",
            samples=40,
            first_s=round(first, 3),
            warm_s=round(time.perf_counter() - t, 3),
        )
    )
    columns = [
        ("task", "{task}"),
        ("samples a record / outcomes a fit", "{samples}"),
        ("first call (s, compiling)", "{first_s}"),
        ("warm (s, best of repeats / all fits)", "{warm_s}"),
    ]
    md = ["# Response spectra and lognormal fits", ""] + markdown_table(rows, columns)
    write_results("spectra", rows, md)


if __name__ == "__main__":
    main()
