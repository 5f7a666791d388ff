#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, to run cluster-configs/prt-farm.slurm for real
# (README.md, "A single-node Slurm cluster"). Debian 12 packages: slurm-wlm (slurmctld, slurmd,
# slurm-client) and munge (scripts/install-deps.sh installs them).
#
#   slurm-local.sh up                        start munged, slurmctld and slurmd; wait for an idle node
#   slurm-local.sh down                      cancel the jobs, stop the daemons (idempotent)
#   slurm-local.sh status                    the daemons, sinfo and squeue
#   slurm-local.sh env                       prints `export SLURM_CONF=...` for sinfo/squeue by hand
#   slurm-local.sh run SCENE OUT [ARGS...]   up if needed, sbatch prt-farm.slurm SCENE OUT ARGS,
#                                            wait for the job, check State=COMPLETED and OUT/report.json
#   slurm-local.sh requeue-test [SCENE OUT [ARGS...]]
#                                            an uninterrupted reference run, then the same run
#                                            interrupted with USR1 (the signal Slurm sends before the
#                                            time limit): it must be requeued, resume from its
#                                            checkpoints, complete, and give the same bytes
#                                            (PRT_REQUEUE_BY=scancel: sent by hand after 10 journaled
#                                            jobs; =time-limit: Slurm sends it, --time=1
#                                            --signal=B:USR1@30)
#   slurm-local.sh clean                     down, then remove the state folder
#
# No systemd: the daemons are started directly, each with the private configuration. All state
# (slurm.conf, the munge key, spool and state folders, logs, pid files) lives in one folder,
# ${PRT_SLURM_DIR:-/tmp/prt-slurm-$USER}, so this never touches /etc/slurm or the system munged.
# As root everything runs directly; as a normal user munged and slurmctld run as that user
# (SlurmUser = the user) and only slurmd, which must be root to start job steps, runs with sudo.
#
# Environment:
#   PRT_SLURM_DIR        the state folder (default /tmp/prt-slurm-$USER)
#   PRT_SLURM_PORT       slurmctld's port; slurmd uses the next one (default 16817, away from
#                        Slurm's 6817/6818 so a real slurmctld on this machine does not clash)
#   PRT_SLURM_NTASKS     MPI ranks of a `run` (default 2, at most the node's CPUs)
#   PRT_SLURM_CPUS_PER_TASK  threads per rank (default the node's CPUs / ranks)
#   PRT_SLURM_TIME       sbatch --time of a `run` (default 30 minutes)
#   PRT_SLURM_WAIT       seconds `run` waits for its job before it gives up (default 3600)
#   PRT_SLURM_SBATCH_ARGS  extra sbatch options of a `run`, split on spaces
#   PRT_FARM             the prt-farm binary (default $PRT_BUILD_DIR/farm/prt-farm, build/ in the
#                        repository); PRT_DATA_PATH is passed to the job with build/data added
#   PRT_LAUNCHER         srun | mpirun | auto (default), read by prt-farm.slurm
#   PRT_SLURM_SUDO       the command for privileged steps when not root (default sudo)
#   PRT_SLURM_RELEASE_REQUEUED  requeue-test: 1 (default) starts a requeued job after 5 s instead
#                        of Slurm's ~2 minutes (scontrol update StartTime=now); 0 waits
set -euo pipefail

HERE=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
ROOT=$(dirname "$HERE")
USER_NAME=$(id -un)
DIR=${PRT_SLURM_DIR:-/tmp/prt-slurm-$USER_NAME}
CTLD_PORT=${PRT_SLURM_PORT:-16817}
SLURMD_PORT=$((CTLD_PORT + 1))
NODE=$(hostname -s)
CLUSTER=prtlocal
PARTITION=local

CONF=$DIR/etc/slurm.conf
MUNGE_DIR=$DIR/munge
MUNGE_SOCKET=$MUNGE_DIR/munge.socket
MUNGE_KEY=$MUNGE_DIR/munge.key
RUN_DIR=$DIR/run                # pid files
LOG_DIR=$DIR/log                # daemon logs and the batch jobs' output
# Every Slurm client of this script (sinfo, sbatch, scontrol, and the srun inside the job, which
# inherits the environment of sbatch) reads this configuration instead of /etc/slurm/slurm.conf.
export SLURM_CONF=$CONF

# Privileged steps: directly as root, with sudo otherwise (PRT_SLURM_SUDO, e.g. "sudo -n" never to
# ask for a password). Only slurmd needs it: starting, stopping, and removing its files.
if [ "$(id -u)" -eq 0 ]; then
  AS_ROOT=()
else
  read -r -a AS_ROOT <<<"${PRT_SLURM_SUDO:-sudo}"
fi
as_root() { "${AS_ROOT[@]}" "$@"; }

log() { echo "slurm-local: $*"; }
die() { echo "slurm-local: error: $*" >&2; exit 1; }

# The daemons live in /usr/sbin, which a normal user's PATH may lack.
PATH=$PATH:/usr/sbin:/sbin
need() {
  local p
  for p in "$@"; do
    command -v "$p" >/dev/null 2>&1 || die "$p not found: install slurm-wlm and munge (scripts/install-deps.sh)"
  done
}

# ---------------------------------------------------------------------------------------------
# Daemons: alive when the pid in their pid file is a process of that name whose command line
# names our state folder (a recycled pid, or the system's own daemon, does not count). /proc is
# readable for root's processes too, so a normal user can check slurmd without sudo.
pid_of() {  # pid_of PIDFILE NAME -> prints the pid of the running daemon, or fails
  local file=$1 name=$2 pid
  [ -r "$file" ] || return 1
  pid=$(cat "$file" 2>/dev/null) || return 1
  [[ "$pid" =~ ^[0-9]+$ ]] || return 1
  [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$name" ] || return 1
  tr '\0' ' ' <"/proc/$pid/cmdline" 2>/dev/null | grep -qF -- "$DIR/" || return 1
  echo "$pid"
}
munged_pid()    { pid_of "$RUN_DIR/munged.pid" munged; }
slurmctld_pid() { pid_of "$RUN_DIR/slurmctld.pid" slurmctld; }
slurmd_pid()    { pid_of "$RUN_DIR/slurmd.pid" slurmd; }

port_busy() {  # something listens on 127.0.0.1:PORT
  (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null
}

# ---------------------------------------------------------------------------------------------
# Configuration
write_conf() {
  # The node as slurmd sees it (CPUs, sockets, cores, threads, RealMemory): a node configured
  # with more than it has would be drained ("Low RealMemory"), so take slurmd's own numbers.
  local hw
  hw=$(slurmd -C | head -n 1 | sed -e 's/^NodeName=[^ ]* *//')
  [ -n "$hw" ] || die "slurmd -C printed nothing"
  local slurm_user=$USER_NAME
  mkdir -p "$DIR/etc"
  # An empty SPANK plug-in stack: /etc/slurm/plugstack.conf belongs to the system.
  : >"$DIR/etc/plugstack.conf"
  cat >"$CONF.new" <<EOF
# Written by cluster-configs/slurm-local.sh: a single-node test cluster; all state in $DIR.
ClusterName=$CLUSTER
SlurmctldHost=$NODE(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
# slurmctld runs as the user who brought the cluster up (root as root); slurmd must be root.
SlurmUser=$slurm_user
SlurmdUser=root
# Our own munged, with its own key and socket (the system munged need not run).
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE_SOCKET
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/slurmd
SlurmctldPidFile=$RUN_DIR/slurmctld.pid
SlurmdPidFile=$RUN_DIR/slurmd.pid
SlurmctldLogFile=$LOG_DIR/slurmctld.log
SlurmdLogFile=$LOG_DIR/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
PlugStackConfig=$DIR/etc/plugstack.conf
MailProg=/bin/true
# No cgroups (a container may not delegate them): track processes by parent pid, no binding.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
# No slurmdbd: no accounting (sacct does not work; scontrol show job does while MinJobAge lasts).
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
# The batch script picks the MPI plug-in (srun --mpi=pmix) or mpirun itself.
MpiDefault=none
# A node that was down comes back by itself when its slurmd registers.
ReturnToService=2
# Jobs may be requeued (prt-farm.slurm asks for it before the time limit).
JobRequeue=1
# Timeouts for a test: finished jobs stay visible to scontrol for an hour; SIGKILL 10 s after
# SIGTERM; no waiting for the other tasks of a step once one ended.
MinJobAge=3600
KillWait=10
Waittime=0
InactiveLimit=0
MessageTimeout=10
SlurmctldTimeout=30
SlurmdTimeout=60
SchedulerType=sched/backfill
NodeName=$NODE NodeAddr=127.0.0.1 $hw State=UNKNOWN
PartitionName=$PARTITION Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
  mv -f "$CONF.new" "$CONF"
}

# ---------------------------------------------------------------------------------------------
# up
start_munged() {
  if munged_pid >/dev/null; then return 0; fi
  # munged insists on a key only its user can read, and on a socket folder everybody may enter
  # (slurmd, as root, and the job's user connect to it).
  mkdir -p "$MUNGE_DIR"
  chmod 0755 "$DIR" "$MUNGE_DIR"
  if [ ! -s "$MUNGE_KEY" ]; then
    mungekey --create --keyfile="$MUNGE_KEY"
    log "created the munge key $MUNGE_KEY"
  fi
  chmod 0600 "$MUNGE_KEY"
  rm -f "$MUNGE_SOCKET" "$MUNGE_SOCKET.lock"
  munged --socket="$MUNGE_SOCKET" --key-file="$MUNGE_KEY" --pid-file="$RUN_DIR/munged.pid" \
         --log-file="$LOG_DIR/munged.log" --seed-file="$MUNGE_DIR/munged.seed" ||
    die "munged did not start; see $LOG_DIR/munged.log"
  for _ in $(seq 50); do
    if munge --socket="$MUNGE_SOCKET" -n </dev/null | unmunge --socket="$MUNGE_SOCKET" >/dev/null 2>&1; then
      log "munged up (socket $MUNGE_SOCKET)"
      return 0
    fi
    sleep 0.2
  done
  die "munged does not answer on $MUNGE_SOCKET; see $LOG_DIR/munged.log"
}

start_slurmctld() {
  if slurmctld_pid >/dev/null; then return 0; fi
  port_busy "$CTLD_PORT" && die "port $CTLD_PORT is taken (another slurmctld?): set PRT_SLURM_PORT"
  mkdir -p "$DIR/state"
  slurmctld -f "$CONF" || die "slurmctld did not start; see $LOG_DIR/slurmctld.log"
  for _ in $(seq 60); do
    if scontrol ping 2>/dev/null | grep -q 'is UP'; then
      log "slurmctld up (port $CTLD_PORT, pid $(slurmctld_pid || echo ?))"
      return 0
    fi
    sleep 0.5
  done
  tail -n 20 "$LOG_DIR/slurmctld.log" >&2 || true
  die "slurmctld does not answer; see $LOG_DIR/slurmctld.log"
}

start_slurmd() {
  if slurmd_pid >/dev/null; then return 0; fi
  port_busy "$SLURMD_PORT" && die "port $SLURMD_PORT is taken (another slurmd?): set PRT_SLURM_PORT"
  as_root mkdir -p "$DIR/slurmd" ||
    die "'${AS_ROOT[*]} mkdir' failed: slurmd must run as root (root, or sudo: PRT_SLURM_SUDO)"
  as_root slurmd -f "$CONF" -N "$NODE" || die "slurmd did not start; see $LOG_DIR/slurmd.log"
  log "slurmd started (port $SLURMD_PORT)"
}

node_state() { sinfo -h -N -n "$NODE" -o '%T' 2>/dev/null | head -n 1; }

wait_node_idle() {
  local state="" resumed=0
  for _ in $(seq 120); do
    state=$(node_state)
    case "$state" in
      idle|mixed|allocated|completing) log "node $NODE is $state"; return 0 ;;
      down*|drain*|fail*)
        # A node that was down before (an old state folder) may need telling it is back.
        if [ $resumed -eq 0 ] && slurmd_pid >/dev/null; then
          log "node $NODE is $state; resuming it"
          scontrol update nodename="$NODE" state=resume 2>/dev/null || true
          resumed=1
        fi ;;
    esac
    sleep 0.5
  done
  sinfo -N -l >&2 || true
  tail -n 20 "$LOG_DIR/slurmd.log" >&2 || true
  die "node $NODE did not become idle (state '$state'); see $LOG_DIR/slurmd.log"
}

cmd_up() {
  need slurmctld slurmd munged mungekey munge sinfo scontrol
  mkdir -p "$DIR" "$RUN_DIR" "$LOG_DIR"
  chmod 0755 "$DIR"
  if slurmctld_pid >/dev/null || slurmd_pid >/dev/null; then
    : # running: keep the configuration the daemons read
  else
    write_conf
  fi
  start_munged
  start_slurmctld
  start_slurmd
  wait_node_idle
}

# ---------------------------------------------------------------------------------------------
# down
wait_gone() {  # wait_gone SECONDS FUNCTION -> true once FUNCTION finds no daemon
  for _ in $(seq $(($1 * 5))); do
    "$2" >/dev/null || return 0
    sleep 0.2
  done
  return 1
}

stop_daemon() {  # stop_daemon NAME PIDFUNC [as_root]
  local name=$1 f=$2 pid
  pid=$("$f") || return 0
  log "stopping $name (pid $pid)"
  if [ "${3:-}" = as_root ]; then as_root kill -TERM "$pid" || true; else kill -TERM "$pid" || true; fi
  wait_gone 20 "$f" && return 0
  log "$name (pid $pid) ignores SIGTERM; SIGKILL"
  if [ "${3:-}" = as_root ]; then as_root kill -KILL "$pid" || true; else kill -KILL "$pid" || true; fi
  wait_gone 5 "$f" || die "cannot stop $name (pid $pid)"
}

cmd_down() {
  need scontrol
  local any=0
  if slurmctld_pid >/dev/null; then
    any=1
    # Cancel what is left so that no job step (slurmstepd outlives slurmd) stays behind.
    local jobs
    jobs=$(squeue -h -o '%i' 2>/dev/null | tr '\n' ' ')
    if [ -n "${jobs// /}" ]; then
      log "cancelling jobs $jobs"
      # shellcheck disable=SC2086
      scancel $jobs 2>/dev/null || true
      for _ in $(seq 60); do
        [ -z "$(squeue -h -o '%i' 2>/dev/null)" ] && break
        sleep 0.5
      done
    fi
    # Shuts slurmctld and every registered slurmd down.
    log "scontrol shutdown (slurmctld pid $(slurmctld_pid || echo ?), slurmd pid $(slurmd_pid || echo ?))"
    scontrol shutdown >/dev/null 2>&1 || true
    wait_gone 20 slurmd_pid || true
    wait_gone 20 slurmctld_pid || true
  fi
  slurmd_pid >/dev/null && any=1
  stop_daemon slurmd slurmd_pid as_root
  stop_daemon slurmctld slurmctld_pid
  if munged_pid >/dev/null; then
    any=1
    stop_daemon munged munged_pid
  fi
  rm -f "$MUNGE_SOCKET" "$MUNGE_SOCKET.lock" 2>/dev/null || true
  if [ $any -eq 1 ]; then log "down (state, logs and the munge key stay in $DIR)"; else log "already down"; fi
}

cmd_status() {
  local name f pid
  for name in munged slurmctld slurmd; do
    f=${name}_pid
    if pid=$("$f"); then echo "$name: running (pid $pid)"; else echo "$name: not running"; fi
  done
  if slurmctld_pid >/dev/null; then
    sinfo -N -l || true
    squeue || true
  fi
}

# ---------------------------------------------------------------------------------------------
# run: one batch job, waited for and checked
farm_env() {
  local build=${PRT_BUILD_DIR:-$ROOT/build}
  export PRT_FARM=${PRT_FARM:-$build/farm/prt-farm}
  [ -x "$PRT_FARM" ] || die "no prt-farm at $PRT_FARM (build it, or set PRT_FARM)"
  PRT_FARM=$(realpath "$PRT_FARM")
  case ":${PRT_DATA_PATH:-}:" in
    *":$build/data:"*) ;;
    *) export PRT_DATA_PATH="$build/data${PRT_DATA_PATH:+:$PRT_DATA_PATH}" ;;
  esac
  # The environment CI uses for MPI ranks on one machine (mpirun as root, shared memory only);
  # sbatch passes the whole environment to the job.
  # shellcheck source-path=SCRIPTDIR
  source "$HERE/ci-two-ranks.env"
}

job_field() {  # job_field JOBID FIELD -> the value of FIELD in `scontrol show job`
  scontrol show job -o "$1" 2>/dev/null | tr ' ' '\n' | sed -n "s/^$2=//p" | head -n 1
}

# sbatch prt-farm.slurm SCENE OUT ARGS on the one node; prints the job id.
submit() {
  local scene=$1 out=$2
  shift 2
  local cpus ntasks cpt
  cpus=$(sinfo -h -N -n "$NODE" -o '%c' | head -n 1)
  ntasks=${PRT_SLURM_NTASKS:-$((cpus >= 2 ? 2 : 1))}
  cpt=${PRT_SLURM_CPUS_PER_TASK:-$((cpus / ntasks > 0 ? cpus / ntasks : 1))}
  local extra=()
  # shellcheck disable=SC2206
  [ -n "${PRT_SLURM_SBATCH_ARGS:-}" ] && extra=(${PRT_SLURM_SBATCH_ARGS})
  # Options on sbatch's command line override the script's #SBATCH lines (8 nodes × 32 cores).
  sbatch --parsable --nodes=1 --ntasks="$ntasks" --ntasks-per-node="$ntasks" \
         --cpus-per-task="$cpt" --time="${PRT_SLURM_TIME:-30}" \
         --output="$LOG_DIR/prt-farm-%j.log" --chdir="$ROOT" "${extra[@]}" \
         "$HERE/prt-farm.slurm" "$scene" "$out" "$@" | cut -d';' -f1
}

# Waits until JOBID ends; prints its state changes (a requeue shows as PENDING again with Restarts
# counting up, then RUNNING); prints the final state.
# Slurm holds a requeued job back for about two minutes (Reason=BeginTime). With
# RELEASE_REQUEUED=1 (the requeue test) it is made eligible after 5 s instead: not at once, since
# slurmd refuses a job whose credential it revoked in the same second ("Job credential revoked",
# and the job ends FAILED).
RELEASE_REQUEUED=0
wait_job() {
  local id=$1 deadline=$((SECONDS + ${PRT_SLURM_WAIT:-3600})) state last="" restarts reason
  local release_at=
  while :; do
    state=$(job_field "$id" JobState)
    restarts=$(job_field "$id" Restarts)
    if [ "$state/$restarts" != "$last" ]; then
      reason=
      [ "$state" = PENDING ] && reason=", reason $(job_field "$id" Reason)"
      log "job $id: $state (restarts ${restarts:-?}$reason)" >&2
      last=$state/$restarts
      if [ "$RELEASE_REQUEUED" -eq 1 ] && [ "$state" = PENDING ] && [ "${restarts:-0}" -gt 0 ]; then
        release_at=$((SECONDS + 5))
      fi
    fi
    if [ -n "$release_at" ] && [ $SECONDS -ge "$release_at" ]; then
      release_at=
      if [ "$state" = PENDING ]; then
        log "job $id: requeued; scontrol update JobId=$id StartTime=now" >&2
        scontrol update JobId="$id" StartTime=now >&2 || true
      fi
    fi
    case "$state" in
      COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|PREEMPTED|OUT_OF_MEMORY|BOOT_FAIL|DEADLINE)
        echo "$state"; return 0 ;;
      "") echo "UNKNOWN"; return 0 ;;  # the controller forgot it (MinJobAge) or died
    esac
    if [ $SECONDS -ge $deadline ]; then
      log "job $id still $state after ${PRT_SLURM_WAIT:-3600} s; cancelling it" >&2
      scancel "$id" || true
      echo "$state"; return 0
    fi
    sleep 1
  done
}

# The run's summary from OUT/report.json; fails when there is none or its status is not ok.
report_line() {
  python3 - "$1/report.json" <<'EOF'
import json, sys
try:
    r = json.load(open(sys.argv[1]))
except (OSError, ValueError) as e:
    sys.exit(f"no readable report: {e}")
j = r.get("jobs", {})
print(f"report: status={r.get('status')} exit_code={r.get('exit_code')} scene={r.get('scene_name')} "
      f"ranks={r.get('ranks')} rows={r.get('rows')} cols={r.get('cols')} "
      f"jobs={j.get('done')}/{j.get('total')} reused={j.get('reused_from_checkpoints')} "
      f"rows_reused={j.get('rows_reused')} rays={r.get('rays_traced_including_reused')} "
      f"wall={r.get('wall_seconds', 0):.1f}s")
sys.exit(0 if r.get("status") == "ok" else 1)
EOF
}

check_job() {  # check_job JOBID STATE OUT -> fails unless COMPLETED with an ok report
  local id=$1 state=$2 out=$3 logf=$LOG_DIR/prt-farm-$1.log ok=1
  log "job $id State=$state (log $logf)"
  [ "$state" = COMPLETED ] || ok=0
  report_line "$out" || ok=0
  if [ $ok -eq 0 ]; then
    [ -f "$logf" ] && tail -n 30 "$logf" >&2
    log "FAILED: job $id ended $state; log $logf" >&2
    return 1
  fi
  [ -f "$out/transport.prtc" ] && log "$(sha256sum "$out/transport.prtc")"
  return 0
}

cmd_run() {
  [ $# -ge 2 ] || die "usage: slurm-local.sh run SCENE OUT [prt-farm args...]"
  local scene out
  scene=$(realpath "$1") || die "no scene $1"
  out=$(realpath -m "$2")
  shift 2
  farm_env
  cmd_up
  local id state
  id=$(submit "$scene" "$out" "$@")
  [ -n "$id" ] || die "sbatch gave no job id"
  log "submitted batch job $id: prt-farm.slurm $scene $out $*"
  state=$(wait_job "$id")
  check_job "$id" "$state" "$out"
}

# ---------------------------------------------------------------------------------------------
# requeue-test: the signal Slurm sends before the time limit (prt-farm.slurm's --signal=B:USR1)
# must end in a requeued job that resumes from its checkpoints and gives the same bytes as an
# uninterrupted run. PRT_REQUEUE_BY=scancel (default) sends the signal by hand once a few jobs are
# journaled; PRT_REQUEUE_BY=time-limit lets Slurm send it: --time=1 --signal=B:USR1@30, so every
# start of the job is stopped and requeued after ~30 s until the run completes.

# A scene that runs ~35 s with 2 ranks on 2 cores (2 ms per sample and rank) in ~85 journaled jobs
# of ~1 s: tests/data's box on a ground of RESOLUTION² samples, n = 16, 1024 rays per texel.
write_requeue_scene() {  # write_requeue_scene FILE RESOLUTION
  cat >"$1" <<EOF
# Written by cluster-configs/slurm-local.sh requeue-test: tests/data/tiny.toml made slow.
[scene]
name = "requeue-test"
n = 16

[[mesh]]
name = "box"
path = "$ROOT/tests/data/box.off"
albedo = [0.5, 0.5, 0.5]

[ground]
enabled = true
size = 3.0
resolution = $2

[sampling]
rays_per_texel = 1024
seed = 3
method = "brute"
EOF
}

journaled_jobs() { grep -c '^job ' "$1/checkpoints/journal.txt" 2>/dev/null || true; }

cmd_requeue_test() {
  local by=${PRT_REQUEUE_BY:-scancel} scene out
  case $by in scancel|time-limit) ;; *) die "PRT_REQUEUE_BY must be scancel or time-limit" ;; esac
  farm_env
  cmd_up
  if [ $# -ge 2 ]; then
    scene=$(realpath "$1") || die "no scene $1"
    out=$(realpath -m "$2")
    shift 2
  else
    [ $# -eq 0 ] || die "usage: slurm-local.sh requeue-test [SCENE OUT [prt-farm args...]]"
    scene=$DIR/requeue-scene-$by.toml
    # Under the time limit each start computes for ~30 s: a run of ~75 s needs 3-4 starts.
    if [ "$by" = time-limit ]; then write_requeue_scene "$scene" 80; else write_requeue_scene "$scene" 56; fi
    out=$DIR/requeue-out-$by
  fi
  # Small jobs, so that a few are journaled well before the run ends.
  export PRT_JOB_SECONDS=${PRT_JOB_SECONDS:-1}
  RELEASE_REQUEUED=${PRT_SLURM_RELEASE_REQUEUED:-1}
  local ref=$out.reference id state t0
  rm -rf "$ref" "$out"

  log "1/2: uninterrupted reference run into $ref"
  t0=$SECONDS
  id=$(PRT_SLURM_TIME=60 submit "$scene" "$ref" "$@")
  log "submitted batch job $id"
  state=$(wait_job "$id")
  check_job "$id" "$state" "$ref" || die "the reference run failed"
  log "reference run took $((SECONDS - t0)) s"

  log "2/2: the same run, interrupted by USR1 ($by), into $out"
  t0=$SECONDS
  if [ "$by" = time-limit ]; then
    # sbatch's command line overrides #SBATCH --signal=B:USR1@300 (more than the whole minute).
    id=$(PRT_SLURM_TIME=1 PRT_SLURM_SBATCH_ARGS="--signal=B:USR1@30 ${PRT_SLURM_SBATCH_ARGS:-}" \
         submit "$scene" "$out" "$@")
    log "submitted batch job $id with --time=1 --signal=B:USR1@30"
  else
    # A time limit well past the script's --signal=B:USR1@300: Slurm's own warning must not come
    # before ours (with a 5-minute limit it came within a second or two, and under load it beat
    # the 10 journaled jobs this waits for).
    id=$(PRT_SLURM_TIME=60 submit "$scene" "$out" "$@")
    log "submitted batch job $id"
    local n=0
    for _ in $(seq 600); do
      n=$(journaled_jobs "$out")
      [ "${n:-0}" -ge 10 ] && break
      state=$(job_field "$id" JobState)
      case "$state" in PENDING|RUNNING|CONFIGURING) ;; *) die "job $id is $state before the signal" ;; esac
      sleep 0.2
    done
    [ "${n:-0}" -ge 10 ] || die "job $id journaled too few jobs in 120 s"
    log "job $id has journaled $n jobs after $((SECONDS - t0)) s: scancel --signal=USR1 --batch $id"
    scancel --signal=USR1 --batch "$id"
  fi
  state=$(wait_job "$id")
  local logf=$LOG_DIR/prt-farm-$id.log restarts
  restarts=$(job_field "$id" Restarts)
  check_job "$id" "$state" "$out" || die "the interrupted run did not complete"
  log "interrupted run took $((SECONDS - t0)) s, restarts=$restarts"

  # The evidence: requeued at least once, each start after the first resumed from the
  # checkpoints, and the output is the reference's, byte for byte.
  local fail=0
  [ "${restarts:-0}" -ge 1 ] || { log "FAILED: job $id was not requeued (Restarts=$restarts)"; fail=1; }
  grep -E -e '^[0-9-]+ [0-9:]+ ' -e '--resume:' "$logf" | sed 's/^/  log: /' || true
  grep -q -e '--resume: .* re-used from checkpoints' "$logf" ||
    { log "FAILED: the log does not show a resume"; fail=1; }
  python3 - "$out/report.json" <<'EOF' || fail=1
import json, sys
j = json.load(open(sys.argv[1]))["jobs"]
print(f"slurm-local: last start: {j['reused_from_checkpoints']} of {j['total']} jobs "
      f"({j['rows_reused']} rows) re-used from checkpoints")
sys.exit(0 if j["reused_from_checkpoints"] > 0 else 1)
EOF
  local f a b
  for f in transport.prtc transport.prtt; do
    [ -f "$ref/$f" ] || continue
    a=$(sha256sum <"$ref/$f" | cut -d' ' -f1)
    b=$(sha256sum <"$out/$f" 2>/dev/null | cut -d' ' -f1)
    if [ "$a" = "$b" ]; then
      log "$f identical to the reference: $a"
    else
      log "FAILED: $f differs from the reference ($a vs $b)"
      fail=1
    fi
  done
  [ $fail -eq 0 ] || die "requeue test failed"
  log "requeue test passed"
}

cmd_clean() {
  cmd_down
  [ -d "$DIR" ] && as_root rm -rf "$DIR"
  log "removed $DIR"
}

case "${1:-}" in
  up) cmd_up ;;
  down) cmd_down ;;
  status) cmd_status ;;
  env) echo "export SLURM_CONF=$CONF" ;;
  run) shift; cmd_run "$@" ;;
  requeue-test) shift; cmd_requeue_test "$@" ;;
  clean) cmd_clean ;;
  *) sed -n '2,/^set -euo/p' "$0" | sed -e '/^set -euo/d' -e 's/^# \{0,1\}//' >&2; exit 2 ;;
esac
