#!/usr/bin/env bash
# The fuzzy and the exploring navigator side by side (issue 23's measure): `hvs sim drive
# --json` with motion noise on, from the maze's 16 start poses and on generated mazes, two
# runs at a time. Prints one line per run (collisions, coverage %, distinct cells, metres,
# cells per metre, explored_s) and the totals per navigator.
#
#   scripts/nav-compare.sh [HVS_BINARY] [OUT_DIR]
#
# SET=maze (the 16 poses of scripts/maze-coverage.sh) or SET=generated (SEEDS, default
# 1..20); DURATION (seconds, default 300); CONTRAST (e.g. 0.2 for plain walls); POLICIES
# (default "fuzzy explore"); SCAN_FILTER (fusion.scan_filter for every policy; by default
# "agreement" for explore and "none" for the others); APPEND (TOML lines appended to every
# config, e.g. $'[nav.scan_match]\nsearch_m = 0.1' to try a setting). About 9 minutes per navigator for 20 runs of 300 s on 2 cores.
set -euo pipefail
BIN=$(realpath -m "${1:-$(dirname "$0")/../target/release/hvs}")
OUT=$(realpath -m "${2:-$(mktemp -d /tmp/hvs-navcmp.XXXXXX)}")
cd "$(dirname "$0")/.."
SET=${SET:-generated}
DURATION=${DURATION:-300}
SEEDS=${SEEDS:-$(seq -s' ' 1 20)}
POLICIES=${POLICIES:-"fuzzy explore"}
. scripts/maze-poses.sh
[ -x "$BIN" ] || { echo "nav-compare: $BIN is not an executable (cargo build --release first)" >&2; exit 2; }
mkdir -p "$OUT"
# One config per navigator, beside config/sim.toml so that its map path resolves (named by
# this shell's pid: two comparisons can run side by side).
TAG="nav-compare-$$"
trap 'rm -f config/.$TAG-*.toml' EXIT
for p in $POLICIES; do
  # The explorer runs with the obstacle scan's agreement filter (fusion.scan_filter), the
  # other policies with the scan they were tuned on; SCAN_FILTER overrides both.
  filter=${SCAN_FILTER:-$([ "$p" = explore ] && echo agreement || echo none)}
  sed -e "s/^policy = \"fuzzy\"/policy = \"$p\"/" \
      -e "s/^scan_filter = \"none\"/scan_filter = \"$filter\"/" config/sim.toml > "config/.$TAG-$p.toml"
  [ -n "${APPEND:-}" ] && printf '\n%s\n' "$APPEND" >> "config/.$TAG-$p.toml"
  grep -q "^policy = \"$p\"" "config/.$TAG-$p.toml" \
    || { echo "nav-compare: could not set policy = \"$p\" in a copy of config/sim.toml" >&2; exit 2; }
  grep -q "^scan_filter = \"$filter\"" "config/.$TAG-$p.toml" \
    || { echo "nav-compare: could not set scan_filter = \"$filter\" in a copy of config/sim.toml" >&2; exit 2; }
done
EXTRA=""
[ -n "${CONTRAST:-}" ] && EXTRA="--wall-contrast $CONTRAST"
export BIN OUT DURATION EXTRA TAG
if [ "$SET" = maze ]; then
  for p in $POLICIES; do for pose in $POSES; do echo "$p pose $pose"; done; done
else
  for p in $POLICIES; do for s in $SEEDS; do echo "$p seed $s"; done; done
fi | xargs -P2 -L1 bash -c '
  if [ "$1" = pose ]; then what="--pose $2"; else what="--maze-seed $2"; fi
  "$BIN" sim drive --config "config/.$TAG-$0.toml" --duration "$DURATION" \
    --motion-noise $what $EXTRA --json > "$OUT/$0_$1_$2.json" \
    || echo "nav-compare: $0 $1 $2 failed" >&2'
python3 - "$OUT" <<'PY'
import glob, json, os, sys
tot = {}
print(f"{'navigator':9s} {'run':22s} {'coll':>4s} {'cov %':>6s} {'cells':>5s} {'m':>6s} {'cells/m':>7s} explored_s")
for f in sorted(glob.glob(os.path.join(sys.argv[1], "*.json"))):
    nav, kind, what = os.path.basename(f)[:-5].split("_", 2)
    try:
        r = json.load(open(f))
    except ValueError:
        print(f"nav-compare: {f}: not JSON (the run failed)", file=sys.stderr)
        continue
    print(f"{nav:9s} {kind + ' ' + what:22s} {r['collisions']:4d} {r['coverage_pct']:6.1f} "
          f"{r['distinct_cells']:5d} {r['distance_m']:6.1f} {r['cells_per_m']:7.2f} {r['explored_s']}")
    t = tot.setdefault(nav, [0, 0, 0.0, 0, 0.0, 0, 0])
    t[0] += 1; t[1] += r["collisions"]; t[2] += r["coverage_pct"]; t[3] += r["distinct_cells"]
    t[4] += r["distance_m"]; t[5] += r["collisions"] == 0; t[6] += r["explored_s"] is not None
for nav, t in tot.items():
    print(f"total {nav}: {t[0]} runs, {t[1]} collisions ({t[5]} runs without), mean coverage "
          f"{t[2] / t[0]:.1f} %, {t[3]} cells, {t[4]:.0f} m, {t[3] / max(t[4], 1e-9):.2f} cells/m, "
          f"{t[6]} runs reached 95 %")
PY
echo "nav-compare: runs in $OUT"
