#!/usr/bin/env bash
# A real Slurm on this one machine (slurmctld + slurmd + munged, started here as root, stopped at the end), two
# worker tasks through deploy/slurm/photon.sbatch, one render, compared bit for bit with the in-process render.
#
#   bash deploy/slurm/test-local.sh [--install]
#
# --install first installs Debian's slurmctld, slurmd, slurm-client and munge. Needs the release binaries
# (cargo build --release -p photon-worker -p photon-coordinator), or PHOTON_BIN=target/debug after `cargo test`.
# Takes about 10 s after that.
set -euo pipefail
cd "$(dirname "$0")/../.."
repo=$(pwd)
if [ "${1:-}" = "--install" ]; then
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null 2>&1 || true
fi
for tool in slurmctld slurmd sbatch munged mungekey; do
  command -v "$tool" >/dev/null || { echo "$tool is missing: run with --install (as root)" >&2; exit 1; }
done
bin=${PHOTON_BIN:-$repo/target/release}
[ -x "$bin/photon-worker" ] && [ -x "$bin/photon-coordinator" ] || { echo "no photon binaries in $bin: build them first" >&2; exit 1; }
bin=$(cd "$bin" && pwd) # the job runs in another folder

D=$(mktemp -d /tmp/photon-slurm.XXXX)
chmod 755 "$D" # munged wants every folder above its socket searchable by all
export SLURM_CONF=$D/etc/slurm.conf
mkdir -p "$D"/{etc,state/ctld,state/d,run,log,out}
mkdir -m700 "$D/munge-key"
mkdir -m755 "$D/munge-run"
host=$(hostname -s)
node=$(slurmd -C | head -1)
cat >"$SLURM_CONF" <<CONF
ClusterName=photonci
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$D/munge-run/munged.sock
StateSaveLocation=$D/state/ctld
SlurmdSpoolDir=$D/state/d
SlurmctldPidFile=$D/run/slurmctld.pid
SlurmdPidFile=$D/run/slurmd.pid
SlurmctldLogFile=$D/log/slurmctld.log
SlurmdLogFile=$D/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MpiDefault=none
MailProg=/bin/true
ReturnToService=2
KillWait=5
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=photonci Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF

pids=()
teardown() {
  scancel --quiet --user=root 2>/dev/null || true
  for _ in $(seq 50); do [ -z "$(squeue -h 2>/dev/null)" ] && break; sleep 0.2; done
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$D"
}
trap teardown EXIT INT TERM

mungekey -c -k "$D/munge-key/munge.key"
munged -F -S "$D/munge-run/munged.sock" --key-file="$D/munge-key/munge.key" \
  --pid-file="$D/munge-run/munged.pid" --seed-file="$D/munge-key/munged.seed" >"$D/log/munged.out" 2>&1 &
pids+=($!)
sleep 0.3
slurmctld -D -i -f "$SLURM_CONF" >"$D/log/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -f "$SLURM_CONF" >"$D/log/slurmd.out" 2>&1 &
pids+=($!)
for _ in $(seq 120); do [ "$(sinfo -h -N -o %t 2>/dev/null)" = idle ] && break; sleep 0.25; done
[ "$(sinfo -h -N -o %t)" = idle ] || { echo "slurm did not come up:"; tail "$D"/log/*; exit 1; }

job_args=(--size 96x72 --spp 8 --integrator photon-map --photons 20000 --no-cache)
out=$D/out
jid=$(cd "$out" && PHOTON_BIN=$bin sbatch --parsable --ntasks=2 --cpus-per-task=1 --chdir="$out" \
  "$repo/deploy/slurm/photon.sbatch" "$repo/scenes/cornell.toml" "$out/slurm.exr" "${job_args[@]}")
echo "submitted job $jid"
state=""
for _ in $(seq 600); do
  state=$(scontrol show job "$jid" | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
  case $state in COMPLETED|FAILED|CANCELLED|TIMEOUT|NODE_FAIL|OUT_OF_MEMORY) break ;; esac
  sleep 0.2
done
cat "$out"/photon-"$jid".out || true
[ "$state" = COMPLETED ] || { echo "job $jid ended $state"; tail -n 20 "$D"/log/*.log; exit 1; }
"$bin/photon-coordinator" render scenes/cornell.toml -o "$out/in-process.exr" -q "${job_args[@]}" >/dev/null
cmp "$out/slurm.exr" "$out/in-process.exr"
workers=$(grep -c 'address = ' "$out"/photon-"$jid".out || true)
echo "OK: job $jid rendered on $workers Slurm worker tasks, identical to the in-process render"
