#!/usr/bin/env bash
# CTest slurm_local (tests/CMakeLists.txt): prt-farm under a real single-node Slurm cluster.
# Brings the cluster of cluster-configs/slurm-local.sh up in a private state folder on free ports,
# runs tests/data/tiny.toml through `sbatch cluster-configs/prt-farm.slurm` (2 ranks) and checks
# State=COMPLETED and report.json, then a scene with a missing mesh, which must end FAILED with
# prt-farm's exit status in the job's log. Whatever happens, the daemons are stopped and the state
# folder removed on the way out (its logs are copied to WORK first).
#
#   slurm_local_test.sh PRT_FARM BUILD_DIR WORK_DIR [requeue]
#
# With `requeue` (CTest slurm_requeue) it runs `slurm-local.sh requeue-test` instead: an
# uninterrupted reference job, then the same job sent USR1 (what Slurm sends before the time
# limit) after 10 journaled jobs, which must requeue itself, resume from its checkpoints,
# complete and give the reference's transport.prtt and transport.prtc byte for byte.
#
# Exit 77 (CTest SKIP_RETURN_CODE) when not root and sudo needs a password: slurmd must be root.
set -euo pipefail

PRT_FARM=${1:?usage: slurm_local_test.sh PRT_FARM BUILD_DIR WORK_DIR}
BUILD_DIR=${2:?usage: slurm_local_test.sh PRT_FARM BUILD_DIR WORK_DIR}
WORK=${3:?usage: slurm_local_test.sh PRT_FARM BUILD_DIR WORK_DIR}
MODE=${4:-run}
SRC=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
LOCAL=$SRC/cluster-configs/slurm-local.sh

if [ "$(id -u)" -ne 0 ] && ! sudo -n true 2>/dev/null; then
  echo "slurm_local_test: not root and no password-less sudo (slurmd must run as root): skipped"
  exit 77
fi
export PRT_SLURM_SUDO="sudo -n"  # never wait for a password

rm -rf "$WORK"
mkdir -p "$WORK"
# The state folder holds munged's socket: keep its path short (a socket path has at most 107
# bytes) and outside the build tree, whose parents munged might find too open.
PRT_SLURM_DIR=$(mktemp -d /tmp/prt-slurm-test.XXXXXX)
export PRT_SLURM_DIR
export PRT_FARM PRT_BUILD_DIR=$BUILD_DIR

# Two free ports (slurmctld, slurmd), away from a cluster brought up by hand on 16817.
port_busy() { (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
port=16827
while port_busy $port || port_busy $((port + 1)); do port=$((port + 2)); done
export PRT_SLURM_PORT=$port

cleanup() {
  local rc=$?
  trap - EXIT INT TERM
  cp -r "$PRT_SLURM_DIR/log" "$WORK/slurm-log" 2>/dev/null || true
  "$LOCAL" clean || rc=1
  echo "slurm_local_test: exit $rc (logs in $WORK/slurm-log)"
  exit $rc
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# Bounded well under the CTest TIMEOUT, so that cleanup always runs (a CTest timeout kills us
# with SIGKILL, which no trap sees, and the daemons would outlive the test).
export PRT_SLURM_WAIT=120
export PRT_SLURM_TIME=5

echo "== up"
timeout 90 "$LOCAL" up

if [ "$MODE" = requeue ]; then
  echo "== requeue-test"
  timeout 300 "$LOCAL" requeue-test | tee "$WORK/requeue.txt"
  grep -q 'requeue test passed' "$WORK/requeue.txt"
  grep -q 'transport.prtc identical to the reference' "$WORK/requeue.txt"
  echo "slurm_local_test: ok"
  exit 0
fi

echo "== run tests/data/tiny.toml"
timeout 150 "$LOCAL" run "$SRC/tests/data/tiny.toml" "$WORK/tiny" | tee "$WORK/run.txt"
grep -q 'State=COMPLETED' "$WORK/run.txt"
grep -q 'report: status=ok .* rows=72 ' "$WORK/run.txt"
log=$(sed -n 's/.*State=COMPLETED (log \(.*\))$/\1/p' "$WORK/run.txt")
grep -q 'prt-farm exited with 0' "$log"

echo "== a failing run: a mesh that does not exist"
printf '[scene]\nname = "missing-mesh"\nn = 8\n\n[[mesh]]\nname = "x"\npath = "no-such-mesh.off"\n' \
  >"$WORK/missing-mesh.toml"
rc=0
timeout 150 "$LOCAL" run "$WORK/missing-mesh.toml" "$WORK/missing-mesh" >"$WORK/fail.txt" 2>&1 || rc=$?
cat "$WORK/fail.txt"
[ "$rc" -ne 0 ]
grep -q 'State=FAILED' "$WORK/fail.txt"
# The batch script reports prt-farm's status (2: bad input) although the launcher failed.
grep -q 'prt-farm exited with 2' "$WORK/fail.txt"

echo "slurm_local_test: ok"
