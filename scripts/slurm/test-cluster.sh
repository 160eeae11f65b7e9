#!/usr/bin/env bash
# A real single-node Slurm cluster in a scratch folder, from Debian's slurm-wlm and munge, for
# the render-farm test (docs/render-farm.md): `start DIR` writes a slurm.conf for this host,
# starts munged, slurmctld and slurmd (as root), waits until the node takes jobs and prints the
# line to source (`export SLURM_CONF=DIR/slurm.conf`); `stop DIR` stops them. Exits 77 (a test's
# skip) when it cannot run here: not root, or the packages are missing.
set -euo pipefail

what=${1:-}
dir=${2:-}
[[ -n $what && -n $dir ]] || { echo "usage: $0 start|stop DIR" >&2; exit 2; }
dir=$(realpath -m "$dir")

# Whether process $1 has exited: gone, or a zombie (its ports and files are released; its
# parent, init here, may take seconds to reap it: about 2 s each on the CI machine).
gone() {
    local stat
    stat=$(cat "/proc/$1/stat" 2>/dev/null) || return 0
    stat=${stat##*) }  # the state follows the command's name, which may hold anything
    [[ $stat == Z* ]]
}

stop() {
    for pidfile in slurmd.pid slurmctld.pid munged.pid; do
        [[ -f $dir/$pidfile ]] || continue
        pid=$(cat "$dir/$pidfile")
        kill "$pid" 2>/dev/null || true
        for _ in $(seq 50); do gone "$pid" && break; sleep 0.1; done
        kill -9 "$pid" 2>/dev/null || true
        rm -f "$dir/$pidfile"
    done
}

if [[ $what == stop ]]; then
    stop
    exit 0
fi
[[ $what == start ]] || { echo "usage: $0 start|stop DIR" >&2; exit 2; }
if [[ $(id -u) -ne 0 ]]; then
    echo "test-cluster: needs root (slurmd runs jobs as their user)" >&2
    exit 77
fi
for tool in munged slurmctld slurmd sbatch sinfo; do
    command -v "$tool" >/dev/null || { echo "test-cluster: $tool missing (Debian: slurm-wlm munge; scripts/setup.sh installs them)" >&2; exit 77; }
done

mkdir -p "$dir"/{state,spool,munge}
chmod 700 "$dir/munge"
host=$(hostname -s)
# Free ports for this cluster alone, so it never meets another on the machine.
read -r ctldPort slurmdPort < <(python3 -c '
import socket
s = [socket.socket() for _ in range(2)]
for x in s: x.bind(("127.0.0.1", 0))
print(*[x.getsockname()[1] for x in s])')
[[ -f $dir/munge/munge.key ]] || { dd if=/dev/urandom of="$dir/munge/munge.key" bs=1024 count=1 status=none; chmod 400 "$dir/munge/munge.key"; }
cat > "$dir/slurm.conf" <<CONF
ClusterName=previstest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctldPort
SlurmdPort=$slurmdPort
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CryptoType=crypto/munge
AuthInfo=socket=$dir/munge/munge.sock
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/builtin
SchedulerParameters=sched_interval=1
MessageTimeout=5
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
MpiDefault=none
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName=$host NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP OverSubscribe=YES
CONF
export SLURM_CONF=$dir/slurm.conf

munged --force --socket="$dir/munge/munge.sock" --key-file="$dir/munge/munge.key" \
    --pid-file="$dir/munged.pid" --log-file="$dir/munged.log" --seed-file="$dir/munge/seed"
slurmctld -D -i -f "$SLURM_CONF" >>"$dir/slurmctld.out" 2>&1 &
echo $! >"$dir/slurmctld.pid"
slurmd -D -f "$SLURM_CONF" >>"$dir/slurmd.out" 2>&1 &
echo $! >"$dir/slurmd.pid"
for _ in $(seq 300); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed|allocated)'; then
        echo "export SLURM_CONF=$SLURM_CONF"
        exit 0
    fi
    sleep 0.1
done
echo "test-cluster: the node did not come up in 30 s; logs in $dir" >&2
tail -5 "$dir"/slurmctld.log "$dir"/slurmd.log "$dir"/munged.log >&2 || true
stop
exit 1
