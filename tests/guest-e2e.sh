#!/bin/sh
# The end-to-end stage of ./run-tests, where vcan is (in the QEMU guest, or natively):
#  1. the pace the bench reaches here (10 s of the GPS-aided drive through vcan, as fast as
#     lockstep with nav lets it go), printed so that a slow host shows at the start of the log;
#  2. the lockstep tests (tests/tests/vcan.rs), several at a time and at the lowest CPU priority
#     (nice 19): their results depend on their scenarios only, however loaded the machine, so
#     they take whatever CPU the rest leaves (the host runs its own stages meanwhile);
#  3. beside them from the start (or, with WAIT_HOST=1, once the host says it is done:
#     SUITE_DIR/host.done, or after 30 minutes), the free-running tests (tests/tests/free.rs)
#     at normal priority, two at a time by default: their verdicts need a machine that keeps
#     real time, and the lockstep tests only take what they leave. The Python device's three
#     tests run first, alone, one after the other: one judges a latency budget set from its
#     own first run, which a neighbour's load would move, and a Python device (the costliest
#     of them to run at x1) beside another free-running test lost its verdict under load.
# Each test runs in a process of its own (tests/src/bin/suite.rs); the results go to SUITE_DIR.
# With JUDGE_DIR, the runs hand their in-process reference, replay and scoring to the judge
# server watching that folder (hil judge-server, on the host: hil::run::offload).
# Usage: guest-e2e.sh HIL SUITE_DIR LOCKSTEP_BINARY FREE_BINARY LOCKSTEP_JOBS FREE_JOBS WAIT_HOST [JUDGE_DIR]
hil="$1" dir="$2" lockstep="$3" free="$4" jobs="$5" free_jobs="$6" wait_host="$7"
[ -n "$8" ] && export HIL_JUDGE_SERVER="$8"
here=$(cd "$(dirname "$0")" && pwd)
suite="$(dirname "$hil")/suite"
out=$(mktemp -d)
"$hil" run --scenario "$here/../scenarios/drive-gps.toml" --duration 10 --speed 1000 \
  --no-reference --iface vcan-pace --json --out "$out/run" >"$out/report.json" 2>"$out/log" || true
pace=$(grep -o '"pace_reached": *[0-9.eE+-]*' "$out/report.json" | head -n 1 | sed 's/.*: *//')
if [ -n "$pace" ]; then
  pace=$(echo "$pace" | awk '{ printf "%.1f", $1 }')
  echo "== the bench's pace here: x$pace (10 s of the GPS-aided drive as fast as it goes, the host busy beside it; docs/ci.md)"
else
  echo "== the bench's pace here: not measured (the probe run failed: $(tail -n 3 "$out/log" | tr '\n' ' '))"
fi
rm -rf "$out"
# the memory while the tests run (the guest's, or natively this machine's): the lowest
# available and the major page faults (pages read again from a file, over 9p from a share),
# printed at the end: a guest short of memory would re-read its programs from this machine and
# stall the runs waiting for them (not seen: 1.4 of 2 GiB left at the lowest, 50 faults)
mem_watch=$(mktemp)
# read with the shell's own builtins, every 5 s: no program started for it in the emulated guest
meminfo() { while read -r k v _; do [ "$k" = "$1:" ] && echo "$((v / 1024))" && return; done </proc/meminfo; }
majfaults() { while read -r k v; do [ "$k" = pgmajfault ] && echo "$v" && return; done </proc/vmstat; }
faults0=$(majfaults)
(
  low=
  while :; do
    a=$(meminfo MemAvailable)
    if [ -z "$low" ] || [ "$a" -lt "$low" ]; then low=$a; echo "$low" >"$mem_watch"; fi
    sleep 5
  done
) &
mem_pid=$!
"$suite" run --binaries "e2e::vcan=$lockstep@$here" --name "end-to-end on vcan (lockstep)" \
  --ignored --jobs "$jobs" --nice 19 --results "$dir/e2e.json" --history "$dir/previous/e2e.json" \
  --slow-first "$here/e2e-slow-first" &
lockstep_pid=$!
if [ "$wait_host" = 1 ]; then
  waited=0
  while [ ! -e "$dir/host.done" ] && [ "$waited" -lt 1800 ]; do
    sleep 1
    waited=$((waited + 1))
  done
  [ -e "$dir/host.done" ] || echo "== the host did not say it was done within 30 minutes: the free-running tests start anyway"
  echo "== the free-running tests start (the host done after $waited s)"
fi
rc=0
"$suite" run --binaries "e2e::free=$free@$here" --name "end-to-end on vcan (free-running)" \
  --ignored --jobs "$free_jobs" --results "$dir/free.json" --history "$dir/previous/free.json" \
  --alone an_independent_python_device_is_judged_by_the_same_checks,an_independent_python_device_that_lies_about_time_is_caught,an_independent_python_device_on_a_labs_contract_whose_clock_drifts_is_caught \
  --slow-first "$here/e2e-slow-first" || rc=1
wait "$lockstep_pid" || rc=1
kill "$mem_pid" 2>/dev/null
echo "== memory where the end-to-end tests ran (the guest, or this machine): $(meminfo MemTotal) MiB, at least $(cat "$mem_watch") MiB available throughout; $(($(majfaults) - faults0)) major page faults"
rm -f "$mem_watch"
exit $rc
