#!/usr/bin/env bash
# Every result a refactor must leave bit for bit as it was, written to folder OUT: the tables of
# every experiment (coning, north-finding, navigation, routes, calibration, each at a small size)
# and the result cards of the north-finding drill and both calibrations (in process: the same
# emulators and nav code as the bench, no guest needed). Run it before and after, then
# `tests/figures.sh --diff A B` compares the two folders (wall-time figures left out).
# An experiment that misses a target exits 1: that is a result too, and the script goes on.
# Usage: tests/figures.sh HIL OUT      (HIL: a release build of hil, e.g. target/release/hil)
#        tests/figures.sh --diff A B
set -euo pipefail
if [ "${1:-}" = --diff ]; then
  # wall times, run folders and dates are not results
  strip() { grep -v -E 'wall|took|elapsed| in [0-9.]+ s|runs/|/tmp/|unix|cpu_s|"t_wall|generated|^date = ' "$1"; }
  rc=0
  for f in $(cd "$2" && find . -type f \( -name '*.md' -o -name '*.txt' -o -name '*.csv' -o -name '*.svg' -o -name '*.json' -o -name '*.toml' \) | sort); do
    if ! diff -q <(strip "$2/$f") <(strip "$3/$f") >/dev/null; then
      echo "differs: $f"; diff <(strip "$2/$f") <(strip "$3/$f") | head -20; rc=1
    fi
  done
  [ $rc = 0 ] && echo "figures equal: $(cd "$2" && find . -type f | wc -l) files"
  exit $rc
fi
hil=$(realpath "$1"); out=$2
mkdir -p "$out"
cd "$(dirname "$0")/.."
step() { echo "== $1 ($SECONDS s)"; }
step coning
"$hil" experiment coning --duration 10 --sweep-step 20 --out "$out/coning" >/dev/null || echo "   (exit status $?: a target not met)"
step north-finding
"$hil" experiment north-finding --runs 6 --dwell 30 --out "$out/north-finding" >/dev/null || echo "   (exit status $?: a target not met)"
step navigation
"$hil" experiment navigation --out "$out/navigation" >/dev/null || echo "   (exit status $?: a target not met)"
step routes
"$hil" experiment routes --scenario scenarios/route-quito-equator.toml --scenario scenarios/route-perth-tunnel.toml --out "$out/routes" >/dev/null || echo "   (exit status $?: a target not met)"
step calibration
"$hil" experiment calibration --runs 2 --duration 300 --out "$out/calibration" >/dev/null || echo "   (exit status $?: a target not met)"
step cards
"$hil" drill north-finding --in-process --heading 123.4 --seed 5 --dwell 30 --out "$out/drill" > "$out/drill-card.txt" || echo "   (exit status $?: a target not met)"
"$hil" calibrate rotating-imu --in-process --rotate 300 --out "$out/rotating-imu" > "$out/rotating-imu-card.txt" || echo "   (exit status $?: a target not met)"
"$hil" calibrate tetrahedral --in-process --monitor --out "$out/tetrahedral" > "$out/tetrahedral-card.txt" || echo "   (exit status $?: a target not met)"
step done
