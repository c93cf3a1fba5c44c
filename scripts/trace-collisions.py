#!/usr/bin/env python3
"""Sorts the collisions of `HVS_DRIVE_TRACE=1 hvs sim drive` traces (stderr) by what the robot
was commanded in the frame before, which footprint end touched, the grid's state at the
touching points and whether their cells ever had a scan point (an end: a touching point in the footprint's front or
rear quarter of its length; "side" when all lie between); prints the nearest occupied
cell's distance per collision (how far aside the grid holds the wall it touched).

    [HALF_LENGTH_M=0.249] scripts/trace-collisions.py TRACE...
"""
import collections
import re
import os
import sys

# The collision line's rim runs from -HALF_LENGTH_M to +HALF_LENGTH_M along the footprint: half
# [robot] length_m (0.438 in config/sim.toml) plus the trace's 0.03 m margin.
HALF_LENGTH_M = float(os.environ.get("HALF_LENGTH_M", "0.249"))


def main(paths):
    kinds = collections.Counter()
    nearest = []
    for path in paths:
        command = "-"
        with open(path) as trace:
            for line in trace:
                if line.startswith("t "):
                    m = re.search(r" mem \S+ \S+ (\w+) dr ", line)
                    command = m.group(1) if m else "-"
                elif line.startswith("collision"):
                    points = [
                        (float(m.group(1)), m.group(2), int(m.group(3)), float(m.group(4)))
                        for m in re.finditer(
                            r"\(([-+.\d]+),[-+.\d]+\) (\w+) h(\d+) near ([\d.]+|inf)", line
                        )
                    ]
                    if not points:
                        continue
                    front = any(a > 0.5 * HALF_LENGTH_M for a, *_ in points)
                    rear = any(a < -0.5 * HALF_LENGTH_M for a, *_ in points)
                    end = "both" if front and rear else "front" if front else "rear" if rear else "side"
                    states = "/".join(sorted({s for _, s, _, _ in points}))
                    seen = "had a point" if any(h > 0 for _, _, h, _ in points) else "never a point"
                    kinds[(command, end, states, seen)] += 1
                    near = min(n for *_, n in points)
                    nearest.append(near)
                    print(f"{path}: t {line.split()[1]} {command} {end} nearest occupied {near:.2f} m")
    print(f"{sum(kinds.values())} collisions (command in the frame before, end, grid state, cells)")
    for kind, n in kinds.most_common():
        print(f"{n:4d} {' '.join(kind)}")
    if nearest:
        nearest.sort()
        print(f"nearest occupied cell: median {nearest[len(nearest) // 2]:.2f} m")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
