#!/usr/bin/env bash
# A single-node Slurm cluster on this machine (slurmctld and slurmd on 127.0.0.1, ports
# 16817 and 16818, munge for authentication), for trying the sbatch job array before a
# real farm, and for the test that runs it (tests/render_cli.rs).
#
#   bash farm/slurm/local-cluster.sh start DIR   # writes DIR/slurm.conf, starts the daemons
#   SLURM_CONF=DIR/slurm.conf sbatch ...          # submit to it
#   bash farm/slurm/local-cluster.sh stop DIR
#
# Needs Debian's slurmctld, slurmd, slurm-client and munge (apt-get install), and root:
# the daemons run as root, with no cgroups (proctrack/linuxproc, task/none). The node
# offers every core and, unless the job asks for none, 1 MB of memory: submit with
# --mem=1M (or 0). Exits non-zero, saying why and with the daemons' last log lines, when
# the cluster does not come up within 10 s.
set -euo pipefail
action=${1:?usage: local-cluster.sh start|stop DIR}
DIR=$(realpath -m "${2:?usage: local-cluster.sh start|stop DIR}")
export SLURM_CONF=$DIR/slurm.conf

stop() {
    for daemon in slurmd slurmctld; do
        if [ -f "$DIR/$daemon.pid" ]; then
            kill "$(cat "$DIR/$daemon.pid")" 2>/dev/null || true
        fi
    done
}

case $action in
stop)
    stop
    exit 0
    ;;
start) ;;
*)
    echo "error: unknown action $action (start or stop)" >&2
    exit 2
    ;;
esac

for program in munged slurmctld slurmd sbatch sinfo; do
    if ! command -v "$program" >/dev/null && [ ! -x "/usr/sbin/$program" ]; then
        echo "error: no $program: apt-get install slurmctld slurmd slurm-client munge" >&2
        exit 1
    fi
done
if [ "$(id -u)" != 0 ]; then
    echo "error: the daemons of a local cluster run as root; run this as root" >&2
    exit 1
fi
mkdir -p "$DIR/state" "$DIR/spool" "$DIR/log"
HOST=$(hostname -s)
cat >"$SLURM_CONF" <<CONF
ClusterName=logsh-local
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CryptoType=crypto/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=local Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
CONF

if ! pgrep -x munged >/dev/null; then
    mkdir -p /run/munge
    chown munge:munge /run/munge 2>/dev/null || true
    runuser -u munge -- /usr/sbin/munged 2>/dev/null || /usr/sbin/munged --force
fi
/usr/sbin/slurmctld -f "$SLURM_CONF"
/usr/sbin/slurmd -f "$SLURM_CONF"
for _ in $(seq 50); do
    if sinfo -h -o %T 2>/dev/null | grep -qx idle; then
        exit 0
    fi
    sleep 0.2
done
echo "error: the local Slurm cluster did not come up within 10 s:" >&2
sinfo >&2 || true
tail -n 5 "$DIR"/log/*.log >&2 || true
stop
exit 1
