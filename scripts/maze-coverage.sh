#!/usr/bin/env bash
# Visit-memory coverage in the maze: `hvs sim drive` from 16 start poses (room centres,
# four headings), 5 simulated minutes each, with the memory on and off, two runs at a time.
# Prints one line per start pose and the totals (docs/navigation.md, "Not done yet").
#
#   scripts/maze-coverage.sh [HVS_BINARY] [OUT_DIR]      (about 12 minutes on 2 cores)
#
# DURATION (seconds, default 300) and POSES ("x,y,deg ...") override the defaults.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${1:-target/release/hvs}
OUT=${2:-$(mktemp -d /tmp/hvs-coverage.XXXXXX)}
DURATION=${DURATION:-300}
. scripts/maze-poses.sh
[ -x "$BIN" ] || { echo "maze-coverage: $BIN is not an executable (cargo build --release first)" >&2; exit 2; }
mkdir -p "$OUT"
export BIN OUT DURATION
for p in $POSES; do for m in on off; do echo "$p $m"; done; done |
  xargs -P2 -L1 bash -c '"$BIN" sim drive --map config/maps/maze.txt --duration "$DURATION" \
    --memory "$1" --pose "$0" --json > "$OUT/$0_$1.json" || echo "maze-coverage: run $0 memory $1 failed" >&2'
python3 - "$OUT" <<'PY'
import glob, json, os, sys
rows = {}
for f in sorted(glob.glob(os.path.join(sys.argv[1], "*.json"))):
    pose, memory = os.path.basename(f)[:-5].rsplit("_", 1)
    try:
        r = json.load(open(f))
    except ValueError:
        print(f"maze-coverage: {f}: not JSON (the run failed)", file=sys.stderr)
        continue
    rows.setdefault(pose, {})[memory] = (r["distinct_cells"], r["collisions"], r["distance_m"])
tot = {"on": [0, 0, 0.0], "off": [0, 0, 0.0]}
print(f"{'start pose':18s} | memory on: cells coll distance | memory off: cells coll distance")
for pose, r in rows.items():
    line = f"{pose:18s}"
    for m in ("on", "off"):
        c, k, d = r.get(m, (0, 0, 0.0))
        tot[m][0] += c; tot[m][1] += k; tot[m][2] += d
        line += f" | {c:4d} {k:2d} {d:5.1f} m"
    print(line)
on, off = tot["on"], tot["off"]
print(f"total ({len(rows)} poses): memory on {on[0]} cells, {on[1]} collisions, {on[2]:.0f} m; "
      f"memory off {off[0]} cells, {off[1]} collisions, {off[2]:.0f} m; on/off cells {on[0] / max(off[0], 1):.2f}")
PY
