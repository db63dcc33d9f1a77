"""Analyses per second against the number of lanes (1e2 .. 1e5), fixed base.

Random (slenderness, size) cells under the San Fernando PCD/SN pulse, in the
default chunks; best of --repeats after compilation. Prints a table and writes
benchmarks/results/scaling.{json,md}. Memory stays bounded: only the results
(eight numbers a lane) grow with the lanes; the peak resident memory is reported.
"""

import argparse
import resource

import numpy as np
from _results import markdown_table, write_results  # noqa: E402

import jaxrock as jr


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--max-lanes", type=int, default=100_000)
    p.add_argument("--repeats", type=int, default=2)
    a = p.parse_args()
    pulse = jr.near_fault_pulse("San Fernando PCD/SN")
    rng = np.random.default_rng(0)
    rows = []
    n = 100
    # Warm up (compile) with a map of one chunk.
    jr.behavior_map(
        np.linspace(2, 6, 4),
        np.linspace(0.5, 2, 4),
        jr.FixedBase(),
        pulse,
        progress=False,
    )
    while n <= a.max_lanes:
        # A grid of n cells: sqrt(n) slendernesses x sqrt(n) sizes, jittered.
        k = int(round(n**0.5))
        lam = np.sort(rng.uniform(1.0, 7.0, k))
        size = np.sort(rng.uniform(0.1, 4.0, n // k))
        best = min(
            jr.behavior_map(lam, size, jr.FixedBase(), pulse, progress=False).seconds
            for _ in range(a.repeats)
        )
        cells = lam.size * size.size
        rows.append(
            dict(
                lanes=cells,
                seconds=best,
                analyses_per_s=cells / best,
                peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            )
        )
        print(rows[-1], flush=True)
        n *= 10
    md = markdown_table(
        rows,
        [
            ("lanes", "{lanes}"),
            ("time (s)", "{seconds:.2f}"),
            ("analyses/s", "{analyses_per_s:.0f}"),
            ("peak RSS (MB)", "{peak_rss_mb:.0f}"),
        ],
    )
    write_results("scaling", rows, md)


if __name__ == "__main__":
    main()
