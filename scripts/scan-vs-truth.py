#!/usr/bin/env python3
"""Compares the obstacle scan with the true walls: reads the `scan` and `truth` lines of
`HVS_DRIVE_TRACE=1 HVS_DRIVE_TRACE_SCAN=1 hvs sim drive` (stderr) and counts, over the bins the
explorer's grid would keep (not left of FIRST_BIN, by default 11 = ceil(max_disp 55 * 64 / 320),
and in a run of RUN bins agreeing within 10 % + 5 cm: [nav.grid] support_share and support_m at
their defaults), those that range past the true wall (deeper than 1.1 x the truth + 5 cm: their ray
clears cells of the wall), those that range short of it, and the rest. Frames taken while the
true heading turned more than 1 degree since the last one are left out (the grid does not add
them either), as are bins whose true wall lies beyond 2.5 m.

    [RUN="2 3"] [FIRST_BIN=11] scripts/scan-vs-truth.py TRACE...
    (RUN: the run lengths to count for; by default the grid's default, 2, and a stricter 3)
"""
import math
import os
import re
import sys

RUNS = [int(r) for r in os.environ.get("RUN", "2 3").split()]
FIRST_BIN = int(os.environ.get("FIRST_BIN", "11"))


def agrees(a, b):
    return a > 0 and b > 0 and abs(a - b) <= 0.1 * b + 0.05


def trusted(ranges, i, run):
    """Bin i lies in a window of `run` consecutive bins that all agree with its depth."""
    n = len(ranges)
    return any(
        all(j == i or agrees(ranges[j], ranges[i]) for j in range(start, start + run))
        for start in range(max(0, i - run + 1), i + 1)
        if start + run <= n
    )


def main(paths):
    for path in paths:
        counts = {run: [0, 0, 0, 0] for run in RUNS}  # past, short, right, at a run's end (past)
        heading = prev_heading = None
        scan = None
        with open(path) as trace:
            for line in trace:
                if line.startswith("t "):
                    m = re.search(r"pose \(\s*[-\d.]+,\s*[-\d.]+,\s*([-\d.]+)\)", line)
                    prev_heading, heading = heading, float(m.group(1)) if m else None
                elif line.startswith("scan "):
                    scan = [float(v) for v in line.split()[3:]]
                elif line.startswith("truth ") and scan:
                    truth = [float(v) for v in line.split()[2:]]
                    if heading is None or prev_heading is None:
                        continue
                    turn = abs((heading - prev_heading + 180.0) % 360.0 - 180.0)
                    if turn > 1.0:
                        continue
                    for i, (r, d) in enumerate(zip(scan, truth)):
                        if i < FIRST_BIN or r <= 0 or d <= 0 or d > 2.5:
                            continue
                        for run in RUNS:
                            if not trusted(scan, i, run):
                                continue
                            c = counts[run]
                            if r > 1.1 * d + 0.05:
                                c[0] += 1
                                edge = (i == 0 or scan[i - 1] <= 0) or (i == len(scan) - 1 or scan[i + 1] <= 0)
                                c[3] += edge
                            elif r < 0.9 * d - 0.05:
                                c[1] += 1
                            else:
                                c[2] += 1
        for run, (past, short, right, edge) in counts.items():
            n = max(1, past + short + right)
            print(
                f"{path}: run {run}: {past + short + right} bins, past the wall {100 * past / n:.2f} % "
                f"(next to an empty bin {100 * edge / n:.2f} %), short of it {100 * short / n:.2f} %"
            )


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
