#!/usr/bin/env bash
# A private single-node Slurm (munged + slurmctld + slurmd on 127.0.0.1) for the cluster test
# (tests/slurm.rs), started as root without systemd; see docs/cluster.md ("Tested against a real Slurm").
#
#   .ci/slurm.sh start DIR   install the packages if missing, write DIR/slurm.conf, start the
#                            daemons, wait until the node is idle; prints SLURM_CONF=DIR/slurm.conf
#   .ci/slurm.sh stop DIR    cancel jobs, kill job steps, stop the daemons by PID
#
# Everything (config, keys, sockets, state, logs, PIDs) lives in DIR. Exit code 0 when the node
# is idle; otherwise non-zero with the reason on stderr (and the daemons stopped again).
set -uo pipefail

say() { echo "slurm.sh: $*" >&2; }
die() { say "$*"; exit 1; }

usage() { die "usage: $0 start|stop DIR"; }
[ $# -eq 2 ] || usage
cmd=$1
dir=$2

# Stops the daemons whose PIDs are in DIR/<name>.pid: SIGTERM to all at once (each takes a
# second or two to save its state), then a bounded wait, then SIGKILL for any still there.
stop_daemons() {
    local name pid live=()
    for name in "$@"; do
        [ -f "$dir/$name.pid" ] || continue
        pid=$(cat "$dir/$name.pid")
        # Only our daemon: a stale PID file must not kill whatever process reuses the number.
        if [ -n "$pid" ] && [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$name" ] \
            && kill -TERM "$pid" 2>/dev/null; then
            live+=("$name:$pid")
        fi
        rm -f "$dir/$name.pid"
    done
    for _ in $(seq 100); do
        local still=()
        for np in "${live[@]}"; do
            kill -0 "${np#*:}" 2>/dev/null && still+=("$np")
        done
        live=("${still[@]}")
        [ ${#live[@]} -eq 0 ] && return 0
        sleep 0.1
    done
    for np in "${live[@]}"; do
        say "${np%%:*} (${np#*:}) ignored SIGTERM for 10 s: SIGKILL"
        kill -KILL "${np#*:}" 2>/dev/null
    done
}

stop() {
    [ -d "$dir" ] || return 0
    if [ -f "$dir/slurm.conf" ] && [ -f "$dir/slurmctld.pid" ]; then
        export SLURM_CONF="$dir/slurm.conf"
        # Jobs first, then whatever job steps are left, then the daemons (killing slurmd alone
        # leaves running steps behind).
        local jobs
        jobs=$(timeout 10 squeue -h -o %A 2>/dev/null | sort -u | tr '\n' ' ')
        if [ -n "${jobs// /}" ]; then
            # shellcheck disable=SC2086
            timeout 10 scancel $jobs 2>/dev/null
        fi
        local pids
        pids=$(timeout 10 scontrol listpids '*' localhost 2>/dev/null | awk 'NR > 1 && $1 ~ /^[0-9]+$/ {print $1}')
        if [ -n "$pids" ]; then
            # shellcheck disable=SC2086
            kill -KILL $pids 2>/dev/null
        fi
    fi
    stop_daemons slurmd slurmctld munged
}

# A TCP port on 127.0.0.1 nobody listens on, from $1 upwards.
free_port() {
    local p=$1
    while (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; do
        p=$((p + 2))
    done
    echo "$p"
}

start() {
    [ "$(id -u)" -eq 0 ] || die "not root: cannot start slurmctld/slurmd here"
    local missing=()
    for b in munged mungekey slurmctld slurmd sbatch squeue sinfo scontrol scancel; do
        command -v "$b" >/dev/null 2>&1 || missing+=("$b")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        command -v apt-get >/dev/null 2>&1 || die "missing ${missing[*]} and no apt-get to install them"
        say "installing slurmctld slurmd slurm-client munge (missing: ${missing[*]})"
        export DEBIAN_FRONTEND=noninteractive
        if ! apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge >"$dir.apt.log" 2>&1; then
            apt-get update >>"$dir.apt.log" 2>&1 || true
            apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge >>"$dir.apt.log" 2>&1 \
                || die "apt-get install failed (log: $dir.apt.log)"
        fi
    fi

    mkdir -p "$dir"/{munge,state,spool} || die "cannot create $dir"
    # munged refuses group- or world-writable directories on the way to its socket and key.
    chmod 755 "$dir" "$dir/munge" "$dir/state" "$dir/spool"
    local m="$dir/munge"
    if [ ! -f "$m/munge.key" ]; then
        mungekey --create --keyfile="$m/munge.key" >/dev/null 2>&1 || die "mungekey failed"
        chmod 600 "$m/munge.key"
    fi
    stop  # leftovers of an earlier start in the same DIR
    munged --foreground --force --key-file="$m/munge.key" --socket="$m/munge.socket" \
        --pid-file="$m/munged.pidfile" --log-file="$m/munged.log" --seed-file="$m/munged.seed" \
        </dev/null >"$m/munged.out" 2>&1 &
    echo $! >"$dir/munged.pid"
    for _ in $(seq 50); do
        [ -S "$m/munge.socket" ] && break
        sleep 0.1
    done
    [ -S "$m/munge.socket" ] || { stop; die "munged did not start (log: $m/munged.log, $m/munged.out)"; }

    local ctld_port slurmd_port cpus
    ctld_port=$(free_port 6817)
    slurmd_port=$(free_port $((ctld_port + 1)))
    cpus=$(nproc)
    cat >"$dir/slurm.conf" <<CONF
# Written by .ci/slurm.sh: a private single-node cluster for tests/slurm.rs.
ClusterName=hvi
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$m/munge.socket
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pidfile
SlurmdPidFile=$dir/slurmd.pidfile
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MailProg=/bin/true
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SchedulerParameters=batch_sched_delay=0
MinJobAge=3600
ReturnToService=2
NodeName=localhost NodeAddr=127.0.0.1 NodeHostname=localhost CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF
    export SLURM_CONF="$dir/slurm.conf"
    slurmctld -D -c -f "$SLURM_CONF" </dev/null >"$dir/slurmctld.out" 2>&1 &
    echo $! >"$dir/slurmctld.pid"
    slurmd -D -N localhost -f "$SLURM_CONF" </dev/null >"$dir/slurmd.out" 2>&1 &
    echo $! >"$dir/slurmd.pid"

    local state=""
    for _ in $(seq 60); do
        state=$(timeout 5 sinfo -h -N -n localhost -o %t 2>/dev/null)
        [ "$state" = idle ] && break
        for d in slurmctld slurmd munged; do
            kill -0 "$(cat "$dir/$d.pid")" 2>/dev/null || {
                stop
                die "$d exited (log: $dir/$d.log, $dir/$d.out)"
            }
        done
        sleep 0.5
    done
    if [ "$state" != idle ]; then
        stop
        die "node not idle after 30 s (state: '${state:-none}'; logs in $dir)"
    fi
    say "single-node Slurm up in $dir (slurmctld port $ctld_port, $cpus CPUs)"
    echo "SLURM_CONF=$SLURM_CONF"
}

case "$cmd" in
start) start ;;
stop) stop ;;
*) usage ;;
esac
