#!/usr/bin/env bash
# A nightly run on a real Slurm cluster: starts a single-node cluster from Debian's slurm-wlm
# (munged, slurmctld and slurmd on localhost; a generated slurm.conf, its own ports, sockets,
# state and spool folders in a temporary folder, all stopped and removed on exit, failure
# included), submits docker/slurm/nightly.sbatch — the batch script users copy — as job arrays
# over the small jobs of tests/nightly/configs into one shared output folder, and checks:
#   night 1   one array of 3 tasks; the task baking the atmosphere job is cancelled (scancel)
#             mid-bake: its report says interrupted, nothing is published, no temporary folder or
#             lock is left; requeued (scontrol requeue), it completes. Every job is built exactly
#             once across the shards, every bundle verifies (`specbake inspect`), and the shard
#             reports merge into one complete night (`specbake report`).
#   night 2   two arrays (3 and 2 tasks) over the same output: every shard finds every bundle up to
#             date and builds nothing.
#   night 3   two arrays (3 and 2 tasks) at once over a fresh output: the per-job lock lets each
#             bundle be built once (reports and bundle folders), and all verify.
#   night 4   only with SPECBAKE_SLURM_TEST_IMAGE (an image built from docker/Dockerfile) and
#             SPECBAKE_SLURM_TEST_ENGINE (podman or docker; apptainer takes docker:// or .sif):
#             one array of 2 tasks running specbake from the image; every job built once, all verify.
# Installs slurm-wlm and munge when missing (as root, or through passwordless sudo). Exits 77
# (skipped) with the reason only when they cannot be installed or the daemons cannot start.
#
#   tests/slurm/slurm_test.sh SPECBAKE_EXE REPO_ROOT
set -euo pipefail
exe=$(realpath "$1")
root=$(realpath "$2")
batch=$root/docker/slurm/nightly.sbatch
configs=$root/tests/nightly/configs
jobs=(bk7-prism sf11-prism sine-grating small-sky) # the jobs of $configs
cancelled_job=small-sky                            # the longest: the one cancelled mid-bake
SECONDS=0

say() { echo "slurm-test: [${SECONDS}s] $*"; }
skip() { echo "slurm-test: SKIP: $*"; exit 77; }
fail() { echo "slurm-test: FAIL: $*" >&2; exit 1; }

# --- Packages and privileges ------------------------------------------------------------------
if [ "$(id -u)" -ne 0 ]; then
  # slurmd launches jobs as their users, which needs root.
  if command -v sudo >/dev/null && sudo -n true 2>/dev/null; then exec sudo -n -E bash "$0" "$@"; fi
  skip "slurmd must run as root (this user is $(id -un), without passwordless sudo)"
fi
tools=(munged munge slurmctld slurmd sbatch squeue scontrol scancel sinfo)
missing_tools() { for t in "${tools[@]}"; do command -v "$t" >/dev/null || return 0; done; return 1; }
if missing_tools; then
  say "installing slurm-wlm and munge"
  install() { DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends slurm-wlm munge >/dev/null; }
  install || { apt-get -o DPkg::Lock::Timeout=600 update -qq && install; } ||
    skip "slurm-wlm and munge are not installed and apt-get cannot install them"
  missing_tools && skip "slurm-wlm is installed but lacks one of: ${tools[*]}"
fi

# --- A single-node cluster in a temporary folder ------------------------------------------------
tmp=$(mktemp -d "${TMPDIR:-/tmp}/specbake-slurm.XXXXXX")
chmod 755 "$tmp" # munged wants every folder above its socket searchable by all
mkdir -p "$tmp"/{etc,run,log,state,spool,reports}
chmod 700 "$tmp/etc"
pids=()
cleanup() {
  local rc=$?
  set +e
  if [ -e "$tmp/slurm.conf" ] && [ -e "$tmp/run/slurmctld.pid" ]; then
    scancel --quiet --user root 2>/dev/null
    for _ in $(seq 1 30); do [ -z "$(squeue -h 2>/dev/null)" ] && break; sleep 0.5; done
  fi
  for f in slurmd slurmctld munged; do
    [ -s "$tmp/run/$f.pid" ] || continue
    local pid
    pid=$(cat "$tmp/run/$f.pid")
    kill "$pid" 2>/dev/null || continue
    for _ in $(seq 1 40); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
    kill -9 "$pid" 2>/dev/null
  done
  if [ "$rc" -ne 0 ] && [ "$rc" -ne 77 ]; then
    for f in "$tmp"/log/*; do echo "--- $f (last lines)"; tail -n 25 "$f"; done >&2
  fi
  rm -rf "$tmp"
  exit "$rc"
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
host=$(hostname -s)
dd if=/dev/urandom of="$tmp/etc/munge.key" bs=1024 count=1 status=none
chmod 400 "$tmp/etc/munge.key"
munged --socket="$tmp/run/munge.sock" --key-file="$tmp/etc/munge.key" --pid-file="$tmp/run/munged.pid" \
  --log-file="$tmp/log/munged.log" --seed-file="$tmp/etc/munged.seed" ||
  skip "munged does not start: $(tail -n 3 "$tmp/log/munged.log" 2>/dev/null)"
munge -n -S "$tmp/run/munge.sock" | unmunge -S "$tmp/run/munge.sock" >/dev/null || skip "munge does not answer on its socket"

# No cgroups, no accounting: process groups track the jobs (proctrack/pgid), tasks are not bound
# (task/none). The node claims 4 CPUs (config_overrides: whatever the machine has) so that two
# arrays of 1-CPU tasks overlap.
cat >"$tmp/slurm.conf" <<CONF
ClusterName=specbake-test
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$tmp/run/munge.sock
CredType=cred/munge
StateSaveLocation=$tmp/state
SlurmdSpoolDir=$tmp/spool
SlurmctldPidFile=$tmp/run/slurmctld.pid
SlurmdPidFile=$tmp/run/slurmd.pid
SlurmctldLogFile=$tmp/log/slurmctld.log
SlurmdLogFile=$tmp/log/slurmd.log
ProctrackType=proctrack/pgid
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SwitchType=switch/none
MpiDefault=none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/builtin
ReturnToService=2
KillWait=20
MinJobAge=600
SlurmdParameters=config_overrides
NodeName=$host NodeAddr=127.0.0.1 CPUs=4 RealMemory=4000 State=UNKNOWN
PartitionName=test Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$tmp/slurm.conf
slurmctld -f "$SLURM_CONF" || skip "slurmctld does not start: $(tail -n 5 "$tmp/log/slurmctld.log" 2>/dev/null)"
slurmd -f "$SLURM_CONF" || skip "slurmd does not start: $(tail -n 5 "$tmp/log/slurmd.log" 2>/dev/null)"
for _ in $(seq 1 60); do
  [ "$(sinfo -h -o %t 2>/dev/null)" = idle ] && break
  sleep 0.5
done
[ "$(sinfo -h -o %t 2>/dev/null)" = idle ] ||
  skip "the Slurm node did not come up: $(sinfo 2>&1 | tail -n 2); $(tail -n 3 "$tmp/log/slurmd.log")"
say "cluster up: $(sinfo -h -o '%P %D node(s) %t, %c CPUs') ($(slurmctld -V))"

# --- Helpers --------------------------------------------------------------------------------------
# submit NAME OUT ARRAY: the nightly batch script as an array into OUT, reports in reports/NAME.
submit() {
  mkdir -p "$tmp/reports/$1"
  SPECBAKE_OUT=$2 SPECBAKE_REPORTS=$tmp/reports/$1 SPECBAKE_CONFIGS=$configs SPECBAKE_BIN=$exe \
    SPECBAKE_IMAGE=${image:-} SPECBAKE_ENGINE=${engine:-} sbatch --parsable --array="$3" --cpus-per-task=1 --job-name="$1" --chdir="$tmp" \
    --output="$tmp/log/$1-%A_%a.out" "$batch"
}
# wait_done JOB...: until no task of the arrays is pending or running (bounded).
wait_done() {
  local list
  list=$(IFS=,; echo "$*")
  for _ in $(seq 1 600); do
    [ -z "$(squeue -h -j "$list" 2>/dev/null)" ] && return 0
    sleep 0.5
  done
  squeue -j "$list" >&2
  fail "arrays $list did not finish within 300 s"
}
# Every task of the array ended COMPLETED with exit 0.
check_completed() {
  local bad
  bad=$(scontrol -o show job "$1" | grep -v 'JobState=COMPLETED .*ExitCode=0:0' | grep -oE 'JobId=[0-9]+ ArrayJobId=[0-9]+ ArrayTaskId=[0-9]+|JobState=[A-Z_]+|ExitCode=[0-9:]+' | paste -sd' ' || true)
  [ -z "$bad" ] || fail "array $1: tasks did not all complete with exit 0: $bad"
}
# Python over JSON (the test's own checks; python3 is part of the build's packages).
py() { python3 -c "$@"; }
# The output folder holds exactly one bundle per job, each verifies, nothing temporary or locked.
check_bundles() {
  local out=$1 job n
  for job in "${jobs[@]}"; do
    n=$(find "$out/$job" -mindepth 1 -maxdepth 1 -type d ! -name '.*' | wc -l)
    [ "$n" -eq 1 ] || fail "$out/$job holds $n bundles, expected 1: $(ls -a "$out/$job")"
    "$exe" inspect "$out/$job" >"$tmp/inspect.txt" 2>&1 || { cat "$tmp/inspect.txt" >&2; fail "$out/$job does not verify"; }
  done
  local left
  left=$(find "$out" -name '.tmp-*' -o -name '.latest-*' -o -name '.lock')
  [ -z "$left" ] || fail "left in $out: $left"
}
# merged NAME...: `specbake report --json` over the reports of the named nights.
merged() {
  local dirs=()
  for n in "$@"; do dirs+=("$tmp/reports/$n"); done
  "$exe" report "${dirs[@]}" --json >"$tmp/night.json" || true
}

# --- Night 1: one array; a task cancelled mid-bake and requeued --------------------------------
# The deterministic split says which of the 3 shards bakes the job to cancel.
shard=""
for i in 0 1 2; do
  "$exe" -q plan "$configs" --out "$tmp/out" --shard "$i/3" --report "$tmp/plan.json"
  if py 'import json, sys; sys.exit(0 if any(j["name"] == sys.argv[2] for j in json.load(open(sys.argv[1]))["jobs"]) else 1)' \
       "$tmp/plan.json" "$cancelled_job"; then shard=$i; fi
done
[ -n "$shard" ] || fail "no shard of 3 plans $cancelled_job"
a=$(submit night1 "$tmp/out" 0-2)
say "night 1: array $a (3 tasks); $cancelled_job is in shard $shard"
lock=$tmp/out/$cancelled_job/.lock
for _ in $(seq 1 1200); do [ -e "$lock" ] && break; sleep 0.1; done
[ -e "$lock" ] || fail "task ${a}_$shard never took $lock"
sleep 0.5
[ ! -e "$tmp/out/$cancelled_job/latest" ] || fail "$cancelled_job was published before it could be cancelled"
scancel "${a}_$shard"
say "cancelled task ${a}_$shard while it baked $cancelled_job (lock held by pid $(cat "$lock" 2>/dev/null || echo '?'))"
for _ in $(seq 1 300); do
  state=$(squeue -h -t all -j "${a}_$shard" -o %T 2>/dev/null)
  [ "$state" = CANCELLED ] && [ -e "$tmp/reports/night1/shard-$shard.json" ] &&
    ! pgrep -f "$tmp/reports/night1/shard-$shard.json" >/dev/null && break
  sleep 0.2
done
[ "$state" = CANCELLED ] || fail "task ${a}_$shard is $state after scancel, expected CANCELLED"
py 'import json, sys
r = json.load(open(sys.argv[1]))
status = {j["name"]: j["status"] for j in r["jobs"]}
assert status.get(sys.argv[2]) == "interrupted", f"the cancelled shard reports {status}"
assert r.get("error") == "stopped by SIGTERM", r.get("error")
print(next(j["reason"] for j in r["jobs"] if j["name"] == sys.argv[2]))' "$tmp/reports/night1/shard-$shard.json" "$cancelled_job" \
  >"$tmp/reason.txt" || fail "the cancelled task's report does not say $cancelled_job was interrupted by SIGTERM"
# (that it was baking is shown by the job's lock it held when cancelled, above: the default
# verbosity logs no "baking" line)
left=$(find "$tmp/out/$cancelled_job" -mindepth 1 2>/dev/null || true)
[ -z "$left" ] || fail "the cancelled bake left: $left"
say "cancelled: the report says interrupted ($(cat "$tmp/reason.txt")); nothing published, no temporary folder, no lock"
scontrol requeue "${a}_$shard"
scontrol update JobId="${a}_$shard" StartTime=now # a requeued job is otherwise held back for 2 minutes
wait_done "$a"
check_completed "$a"
grep -q 'restart 1' "$tmp/log/night1-${a}_$shard.out" || fail "task ${a}_$shard did not run again after requeue"
check_bundles "$tmp/out"
merged night1
py 'import json, sys
n = json.load(open(sys.argv[1])); want = sorted(sys.argv[2:])
assert sorted(j["name"] for j in n["jobs"]) == want, [j["name"] for j in n["jobs"]]
for j in n["jobs"]:
    assert j["status"] == "built" and j["builds"] == 1, (j["name"], j["status"], j["builds"])
assert sorted(s["index"] for s in n["shards"]) == [0, 1, 2] and {s["count"] for s in n["shards"]} == {3}, n["shards"]
assert not n["failed"], n["problems"]' "$tmp/night.json" "${jobs[@]}" || fail "night 1's merged report: $(cat "$tmp/night.json")"
"$exe" report "$tmp/reports/night1" || fail "specbake report says night 1 failed"
say "night 1: every job built exactly once across the shards, every bundle verifies, the reports merge"

# --- Night 2: two arrays over the built output: every shard finds every bundle up to date -----------
b=$(submit night2a "$tmp/out" 0-2)
c=$(submit night2b "$tmp/out" 0-1)
wait_done "$b" "$c"
check_completed "$b"
check_completed "$c"
check_bundles "$tmp/out"
for n in night2a night2b; do
  merged "$n"
  py 'import json, sys
n = json.load(open(sys.argv[1]))
assert sorted(j["name"] for j in n["jobs"]) == sorted(sys.argv[2:]), [j["name"] for j in n["jobs"]]
for j in n["jobs"]:
    for e in j["entries"]:
        assert e["status"] == "up-to-date", (j["name"], e)
assert not n["failed"], n["problems"]' "$tmp/night.json" "${jobs[@]}" || fail "$n rebuilt something: $(cat "$tmp/night.json")"
done
say "night 2: arrays $b and $c found every bundle of night 1 up to date in every shard"

# --- Night 3: two arrays at once over a fresh output: each bundle built once ------------------------
d=$(submit night3a "$tmp/out3" 0-2)
e=$(submit night3b "$tmp/out3" 0-1)
wait_done "$d" "$e"
check_completed "$d"
check_completed "$e"
check_bundles "$tmp/out3"
merged night3a night3b
py 'import json, sys
n = json.load(open(sys.argv[1]))
assert sorted(j["name"] for j in n["jobs"]) == sorted(sys.argv[2:]), [j["name"] for j in n["jobs"]]
for j in n["jobs"]:
    statuses = sorted(e["status"] for e in j["entries"])
    assert statuses == ["built", "up-to-date"], (j["name"], statuses)
assert n["summary"]["built_twice"] == 0 and not n["failed"], n' "$tmp/night.json" "${jobs[@]}" ||
  fail "two arrays over one output: $(cat "$tmp/night.json")"
"$exe" report "$tmp/reports/night3a" "$tmp/reports/night3b" || fail "specbake report says night 3 failed"
say "night 3: arrays $d and $e over one fresh output built each bundle once (the other shard found it up to date)"
# --- Night 4 (by request): specbake from the container image --------------------------------------
image=${SPECBAKE_SLURM_TEST_IMAGE:-}
engine=${SPECBAKE_SLURM_TEST_ENGINE:-}
if [ -n "$image" ]; then
  f=$(submit night4 "$tmp/out4" 0-1)
  wait_done "$f"
  check_completed "$f"
  check_bundles "$tmp/out4"
  merged night4
  py 'import json, sys
n = json.load(open(sys.argv[1]))
assert sorted(j["name"] for j in n["jobs"]) == sorted(sys.argv[2:]), [j["name"] for j in n["jobs"]]
for j in n["jobs"]:
    assert j["status"] == "built" and j["builds"] == 1, (j["name"], j["status"], j["builds"])
assert not n["failed"], n["problems"]' "$tmp/night.json" "${jobs[@]}" || fail "night 4 (image $image): $(cat "$tmp/night.json")"
  say "night 4: array $f ran specbake from $image through ${engine:-apptainer}: every job built once, all verify"
fi
say "PASS"
