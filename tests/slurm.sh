#!/usr/bin/env bash
# A real single-node Slurm cluster on this machine, and a north-finding Monte Carlo run on it in
# parts: Debian's slurmctld, slurmd and munged started here (no systemd), their state, logs and
# config in a temporary folder. The Monte Carlo goes in as a job array of four parts
# (`sbatch --array=0-3`, each task `hil experiment north-finding --shard $SLURM_ARRAY_TASK_ID/4`),
# the merge as a job that depends on the whole array (`--dependency=afterok`). The merged report
# must equal a single run's table for table. Then the cluster stops, leaving nothing running.
#
# With FAIL_PART=K, array task K fails on purpose: the merge job never runs (its dependency
# cannot be met), `hil experiment merge` of the parts there are names the missing part and the
# runs it held, and a rerun of that part alone, then a merge job after it, completes the report.
#
# With CAMPAIGN=FILE, a regression campaign then runs on the same cluster (`hil campaign`): a job
# array of two parts (`--shard K/2`, each part's cells on vcan in a guest of its own where this
# kernel has no CAN, its experiments' runs in process here), one cell of part 1 killed on purpose
# while it runs (`scancel`), the plan asked which cells have no result (that one alone), it
# resubmitted as a job array of that cell, the merge a job after it; its report must give the
# verdicts CAMPAIGN_EXPECT names. (`./run-tests` compares it with the local pool's report of the
# same campaign through vcan: tests/tests/campaign.rs.)
#
# Usage: tests/slurm.sh HIL [OUT]   (HIL: the hil binary; OUT: where the reports go, kept)
# Needs root (munged and slurmd run as root here) and the packages slurmctld, slurmd,
# slurm-client and munge (./run-tests installs them). Environment: RUNS (default 1) and DWELL
# (default 10 s) size the Monte Carlo; KEEP=1 keeps the cluster's folder.
set -euo pipefail
hil=$(realpath "$1")
out=$(realpath -m "${2:-$(mktemp -d /tmp/hil-slurm-out.XXXXXX)}")
runs=${RUNS:-1}
dwell=${DWELL:-10}
parts=4
# a fresh start: parts left from an earlier run must not complete this one
rm -rf "$out/parts" "$out/merged" "$out/single" "$out/incomplete"
for c in slurmctld slurmd munged sbatch scontrol; do
  command -v "$c" >/dev/null || { echo "slurm.sh: $c is missing (apt-get install slurmctld slurmd slurm-client munge)" >&2; exit 2; }
done
state=$(mktemp -d /tmp/hil-slurm.XXXXXX)
host=$(hostname -s)
started=$SECONDS

stop_cluster() {
  for p in slurmd slurmctld munged; do
    if [ -s "$state/$p.pid" ]; then
      kill "$(cat "$state/$p.pid")" 2>/dev/null || true
    fi
  done
  # wait for them to go, so that nothing is left running
  for _ in $(seq 50); do
    alive=0
    for p in slurmd slurmctld munged; do
      [ -s "$state/$p.pid" ] && kill -0 "$(cat "$state/$p.pid")" 2>/dev/null && alive=1
    done
    [ $alive = 0 ] && break
    sleep 0.2
  done
  if [ "${KEEP:-0}" = 1 ]; then
    echo "slurm.sh: the cluster's folder is kept: $state"
  else
    rm -rf "$state"
  fi
}
trap stop_cluster EXIT

# munge: its own key, socket and state
mkdir -p "$state"/{munge,spool,ctld,log,jobs}
chmod 700 "$state/munge"
head -c 1024 /dev/urandom > "$state/munge/munge.key"
chmod 400 "$state/munge/munge.key"
munged --force --key-file="$state/munge/munge.key" --socket="$state/munge/munge.socket" \
  --pid-file="$state/munged.pid" --log-file="$state/log/munged.log" \
  --seed-file="$state/munge/munged.seed"

# two free ports for the controller and the node daemon
ports=$(python3 -c 'import socket
s=[socket.socket() for _ in range(2)]
[x.bind(("127.0.0.1",0)) for x in s]
print(" ".join(str(x.getsockname()[1]) for x in s))')
read -r ctld_port slurmd_port <<<"$ports"
cpus=$(nproc)
mem=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 / 2 ))
cat > "$state/slurm.conf" <<EOF
ClusterName=hil
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
AuthInfo=socket=$state/munge/munge.socket
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/spool
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=$state/log/slurmctld.log
SlurmdLogFile=$state/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=hil Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$state/slurm.conf"
slurmctld -f "$SLURM_CONF"
slurmd -f "$SLURM_CONF"

# the node comes up (idle) within a minute, or the cluster did not start
for i in $(seq 120); do
  st=$(scontrol show node "$host" -o 2>/dev/null | sed -n 's/.*State=\([A-Z+_]*\).*/\1/p')
  case "$st" in IDLE*) break ;; esac
  if [ "$i" = 120 ]; then
    echo "slurm.sh: node $host not idle after 60 s (state '${st:-none}'); the daemons' logs:" >&2
    tail -n 20 "$state"/log/*.log >&2
    exit 1
  fi
  sleep 0.5
done
echo "== a single-node Slurm cluster is up ($((SECONDS - started)) s): node $host, $cpus CPUs, controller on port $ctld_port"

mc=(experiment north-finding --runs "$runs" --dwell "$dwell")
part_files=$(for k in $(seq 0 $((parts - 1))); do printf "'%s' " "$out/parts/part-$k-of-$parts.json"; done)
fail=${FAIL_PART:-}
array=$(sbatch --parsable --job-name=nf-mc --array=0-$((parts - 1)) --cpus-per-task=1 \
  --output="$state/jobs/part-%a.log" \
  --wrap "if [ \"\$SLURM_ARRAY_TASK_ID\" = '$fail' ]; then echo 'part failing on purpose (FAIL_PART)' >&2; exit 3; fi; exec '$hil' ${mc[*]} --shard \$SLURM_ARRAY_TASK_ID/$parts --out '$out/parts'")
merge=$(sbatch --parsable --job-name=nf-merge --dependency=afterok:"$array" --kill-on-invalid-dep=yes \
  --output="$state/jobs/merge.log" --wrap "exec '$hil' experiment merge $part_files --out '$out/merged'")
echo "== submitted: the Monte Carlo as job array $array (${parts} parts), the merge as job $merge (afterok:$array)"

# a job's end (a limit, so that a broken cluster fails rather than hangs): its final state
state_of() { scontrol show job "$1" -o 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' | sort -u | tr '\n' ' '; }
limit=${SLURM_LIMIT_S:-900}
wait_job() {
  local t0=$SECONDS m
  while true; do
    m=$(state_of "$1")
    case "$m" in
      *PENDING*|*RUNNING*|*CONFIGURING*|*COMPLETING*|"") ;;
      *) echo "$m"; return ;;
    esac
    if [ $((SECONDS - t0)) -gt "$limit" ]; then
      echo "slurm.sh: job $1 is still '$m' after $limit s; the array's tasks: $(state_of "$array")" >&2
      exit 1
    fi
    sleep 1
  done
}
m=$(wait_job "$merge")
if [ -n "$fail" ]; then
  case "$m" in *COMPLETED*) echo "slurm.sh: the merge ran though part $fail failed" >&2; exit 1 ;; esac
  echo "== part $fail failed on purpose; the merge job ended $m (its dependency could not be met)"
  if "$hil" experiment merge $(ls "$out"/parts/part-*-of-$parts.json) --out "$out/incomplete" > "$state/merge-error.txt" 2>&1; then
    echo "slurm.sh: merging without part $fail succeeded" >&2; exit 1
  fi
  grep -o "part $fail of $parts (Slurm array task $fail[^;]*" "$state/merge-error.txt" | sed 's/^/   merge says: /' || {
    echo "slurm.sh: the merge's error does not name part $fail:" >&2; cat "$state/merge-error.txt" >&2; exit 1; }
  rerun=$(sbatch --parsable --job-name=nf-rerun --output="$state/jobs/rerun-$fail.log" \
    --wrap "exec '$hil' ${mc[*]} --shard $fail/$parts --out '$out/parts'")
  merge=$(sbatch --parsable --job-name=nf-merge --dependency=afterok:"$rerun" --kill-on-invalid-dep=yes \
    --output="$state/jobs/merge.log" --wrap "exec '$hil' experiment merge $part_files --out '$out/merged'")
  echo "== part $fail submitted again as job $rerun, the merge as job $merge (afterok:$rerun)"
  m=$(wait_job "$merge")
fi
case "$m" in
  *COMPLETED*) ;;
  *) echo "slurm.sh: the merge job ended $m; the array's tasks: $(state_of "$array")" >&2
     tail -n 5 "$state"/jobs/*.log >&2
     exit 1 ;;
esac
echo "== the jobs, as Slurm ran them:"
scontrol show job "$array" -o | sed -n 's/.*JobId=\([0-9]*\).*ArrayTaskId=\([0-9]*\).*JobState=\([A-Z]*\).*RunTime=\([0-9:]*\).*/   array task \2 (job \1): \3, run time \4/p'
[ -n "$fail" ] && scontrol show job "$rerun" -o | sed -n 's/.*JobId=\([0-9]*\).*RunTime=\([0-9:]*\).*/   part '"$fail"' again (job \1): run time \2/p'
scontrol show job "$merge" -o | sed -n 's/.*JobId=\([0-9]*\).*RunTime=\([0-9:]*\).*/   merge (job \1): run time \2/p'
cluster_s=$((SECONDS - started))

# the same Monte Carlo in one piece, here
"$hil" "${mc[@]}" --out "$out/single" >/dev/null || true
# table for table: the reports' Markdown and the runs
strip() { grep -v -E 'wall|took|elapsed|runs/|/tmp/|files:' "$1"; }
rc=0
for f in report.md runs.csv; do
  if ! diff <(strip "$out/single/$f") <(strip "$out/merged/$f") >/dev/null; then
    echo "slurm.sh: $f of the merged parts differs from the single run's:" >&2
    diff <(strip "$out/single/$f") <(strip "$out/merged/$f") | head -20 >&2
    rc=1
  fi
done
[ $rc = 0 ] || exit 1
echo "== the merged report equals the single run's (report.md, runs.csv): the cluster's part took $cluster_s s, $((SECONDS - started)) s in all; reports in $out"

[ -n "${CAMPAIGN:-}" ] || exit 0
camp=$(realpath "$CAMPAIGN")
cout="$out/campaign"
rm -rf "$cout"
t0=$SECONDS
# the plan's cells as "number key on-the-bus done" lines
plan_lines() {
  "$hil" campaign "$camp" --plan --json --out "$cout" | python3 -c '
import json, sys
for c in json.load(sys.stdin):
    print(c["cell"], c["key"], int(not c["case"].startswith("experiment:")), int(c["done"]))'
}
cells=$(plan_lines)
# the cell killed on purpose: part 1's last cell on the bus (its part's cells run in order, so
# every other cell of the part has its result by then)
kill_cell=$(awk '$1 % 2 == 1 && $3 == 1 { n = $1; k = $2 } END { print n, k }' <<<"$cells")
read -r kill_n kill_key <<<"$kill_cell"
carray=$(sbatch --parsable --job-name=campaign --array=0-1 --cpus-per-task=1 \
  --output="$state/jobs/campaign-%a.log" \
  --wrap "exec '$hil' campaign '$camp' --shard \$SLURM_ARRAY_TASK_ID/2 --out '$cout' --iface-prefix vcan-p\$SLURM_ARRAY_TASK_ID-")
echo "== campaign $(basename "$camp"): $(wc -l <<<"$cells") cells as job array $carray (2 parts); cell $kill_n to be killed while it runs"
# its folder appears when it starts: then the task running it is cancelled
for _ in $(seq $((limit * 5))); do
  [ -d "$cout/cells/$kill_key" ] && break
  case "$(state_of "$carray")" in *PENDING*|*RUNNING*|*CONFIGURING*) ;; *) break ;; esac
  sleep 0.2
done
[ -d "$cout/cells/$kill_key" ] || { echo "slurm.sh: cell $kill_n never started; the array: $(state_of "$carray")" >&2; tail -n 20 "$state"/jobs/campaign-*.log >&2; exit 1; }
sleep 2
scancel "${carray}_1"
m=$(wait_job "$carray")
echo "== cell $kill_n killed while it ran (scancel of array task 1); the array ended $m"
missing=$(plan_lines | awk '$4 == 0 { print $1 }' | paste -sd, -)
if [ "$missing" != "$kill_n" ]; then
  echo "slurm.sh: the cells without a result are '$missing', not the killed one alone ($kill_n); the parts' logs:" >&2
  tail -n 20 "$state"/jobs/campaign-*.log >&2
  exit 1
fi
rerun=$(sbatch --parsable --job-name=campaign-rerun --array="$missing" --output="$state/jobs/campaign-rerun-%a.log" \
  --wrap "exec '$hil' campaign '$camp' --cell \$SLURM_ARRAY_TASK_ID --out '$cout' --iface-prefix vcan-r")
# the merge's exit status is the campaign's (1: a regression found): kept, the job itself ends well
cmerge=$(sbatch --parsable --job-name=campaign-merge --dependency=afterok:"$rerun" --kill-on-invalid-dep=yes \
  --output="$state/jobs/campaign-merge.log" \
  --wrap "'$hil' campaign '$camp' --merge --out '$cout' > '$cout/merge.out'; echo \$? > '$cout/merge.status'")
echo "== the cell without a result, $missing, submitted again alone as job array $rerun, the merge as job $cmerge (afterok:$rerun)"
m=$(wait_job "$cmerge")
case "$m" in *COMPLETED*) ;; *) echo "slurm.sh: the campaign's merge ended $m" >&2; tail -n 20 "$state"/jobs/campaign-*.log >&2; exit 1 ;; esac
status=$(cat "$cout/merge.status")
echo "== the cluster's campaign: merged (exit status $status), $((SECONDS - t0)) s"
rc=0
# the verdicts the campaign's file promises (CAMPAIGN_EXPECT: "case=verdict ..." for its one
# device beside the baseline)
for want in ${CAMPAIGN_EXPECT:-}; do
  got=$(python3 -c '
import json, sys
m = json.load(open(sys.argv[1]))
print(" ".join(v["verdict"] for v in m["verdicts"] if v["case"] == sys.argv[2]) or "none")' "$cout/report.json" "${want%%=*}")
  if [ "$got" != "${want#*=}" ]; then
    echo "slurm.sh: the campaign's verdict on ${want%%=*} is '$got', not ${want#*=}:" >&2
    cat "$cout/report.md" >&2
    rc=1
  fi
done
if [ -n "${CAMPAIGN_STATUS:-}" ] && [ "$status" != "$CAMPAIGN_STATUS" ]; then
  echo "slurm.sh: the campaign's merge exited $status, not $CAMPAIGN_STATUS" >&2
  rc=1
fi
[ $rc = 0 ] || exit 1
[ -z "${CAMPAIGN_EXPECT:-}" ] || echo "== the verdicts: ${CAMPAIGN_EXPECT} (exit status $status)"
echo "== the cluster's campaign report is in $cout (the local pool's must be the same: tests/tests/campaign.rs)"
