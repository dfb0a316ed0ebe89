#!/bin/sh
# The end-to-end stage of ./run-tests, where vcan is (in the QEMU guest, or natively): first
# the pace the bench reaches here (10 s of the GPS-aided drive through vcan, as fast as lockstep
# with nav lets it go), printed so that a slow host shows at the start of the log; then the
# end-to-end tests, each in a process of its own, several at a time (tests/src/bin/suite.rs).
# Usage: guest-e2e.sh HIL_BINARY [suite run arguments...]
hil="$1"
shift
here=$(cd "$(dirname "$0")" && pwd)
out=$(mktemp -d)
"$hil" run --scenario "$here/../scenarios/drive-gps.toml" --duration 10 --speed 1000 \
  --no-reference --iface vcan-pace --json --out "$out/run" >"$out/report.json" 2>"$out/log" || true
pace=$(grep -o '"pace_reached": *[0-9.eE+-]*' "$out/report.json" | head -n 1 | sed 's/.*: *//')
if [ -n "$pace" ]; then
  pace=$(echo "$pace" | awk '{ printf "%.1f", $1 }')
  echo "== the bench's pace here: x$pace (10 s of the GPS-aided drive as fast as it goes; ./run-tests fits 15 minutes where this is x5 or more, docs/pace.md)"
else
  echo "== the bench's pace here: not measured (the probe run failed: $(tail -n 3 "$out/log" | tr '\n' ' '))"
fi
rm -rf "$out"
exec "$(dirname "$hil")/suite" run "$@"
