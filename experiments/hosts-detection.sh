#!/usr/bin/env bash
# How fast a learner notices a relay that is killed, frozen or cut off, and a relay its killed
# learner: the time from the fault to the log line that reports it, over a few trials each.
#
#   experiments/hosts-detection.sh [TRIALS] [LEASE]      (default 5 trials, lease 3 s)
#
# Needs a release build (cargo build --release). The network cut needs root and iproute2 (a
# network namespace with a link taken down); without them that row is skipped.
set -euo pipefail
shopt -s inherit_errexit
trials=${1:-5}
lease=${2:-3}
acps=${ACPS:-$(dirname "$0")/../target/release/acps}
work=$(mktemp -d /tmp/acps-detection-XXXXXX)
ns=""
cleanup() {
    # Interrupted, the learners and relays remove their shared memory; then nothing is left.
    pkill -INT -f "det$$-" 2>/dev/null && sleep 2
    pkill -KILL -f "det$$-" 2>/dev/null || true
    if [ -n "$ns" ]; then
        ip link del acpsdet-h 2>/dev/null || true
        ip netns del "$ns" 2>/dev/null || true
    fi
    rm -rf "$work"
}
trap cleanup EXIT

# The first log line at or after the fault that matches PATTERN, as seconds since the epoch.
seen() { # LOG PATTERN LIMIT_S
    local deadline=$((SECONDS + $3))
    while [ $SECONDS -lt $deadline ]; do
        local line
        line=$(sed 's/\x1b\[[0-9;]*m//g' "$1" | grep -m1 -E "$2" || true)
        if [ -n "$line" ]; then
            date -d "$(cut -d' ' -f1 <<<"$line")" +%s.%N
            return
        fi
        sleep 0.01
    done
    echo "gave up waiting for '$2' in $1" >&2
    return 1
}

waitfor() { # LOG PATTERN
    local deadline=$((SECONDS + 60))
    until grep -q -E "$2" "$1" 2>/dev/null; do
        [ $SECONDS -lt $deadline ] || { echo "gave up waiting for '$2' in $1" >&2; return 1; }
        sleep 0.01
    done
}

# One trial: a learner and a relay; FAULT is applied once the relay is admitted.
trial() { # FAULT INDEX
    local fault=$1 i=$2 host="127.0.0.1" inside=()
    if [ "$fault" = cut ]; then
        host="198.18.250.1"
        inside=(ip netns exec "$ns")
    fi
    local port=$((17600 + RANDOM % 2000)) dir="$work/$fault-$i"
    mkdir -p "$dir"
    "$acps" run grid --sim analytic --runs 1 --episodes 1000000 --method monotonic-progress --workers 0 -v \
        --listen "tcp/$host:$port" --lease "$lease" --run "det$$-$fault-$i" --out "$dir/out" \
        >"$dir/learner.log" 2>&1 &
    local learner=$!
    waitfor "$dir/learner.log" "serves relays at"
    setsid "${inside[@]}" "$acps" relay --connect "tcp/$host:$port" --relay-key "$dir/out/relay.key" --workers 1 --lease "$lease" \
        --local-run "det$$-$fault-$i-h" --wait-for-learner 1 -v >"$dir/relay.log" 2>&1 &
    local relay=$!
    waitfor "$dir/learner.log" "admitted the relay"
    sleep 0.5 # serving for a while, not just admitted
    local start log pattern
    start=$(date +%s.%N)
    case $fault in
        kill) kill -KILL -- "-$relay" ;;
        freeze) kill -STOP -- "-$relay" ;;
        cut) ip link set acpsdet-h down ;;
        learner) kill -KILL "$learner" ;;
    esac
    if [ "$fault" = learner ]; then
        log="$dir/relay.log" pattern="the learner of run .* is gone"
    else
        log="$dir/learner.log" pattern="\(peer [0-9]+\) is gone|remote peer [0-9]+ is gone|given up"
    fi
    local at
    at=$(seen "$log" "$pattern" 60)
    python3 -c "print(f'{1000 * ($at - $start):.0f}')"
    [ "$fault" = cut ] && ip link set acpsdet-h up
    kill -CONT -- "-$relay" 2>/dev/null || true
    kill -INT -- "-$relay" 2>/dev/null || true
    kill -INT "$learner" 2>/dev/null || true
    wait "$learner" 2>/dev/null || true
    wait "$relay" 2>/dev/null || true
    return 0
}

faults=(kill freeze learner)
if [ "$(id -u)" = 0 ] && command -v ip >/dev/null; then
    ns="acpsdet$$"
    ip netns add "$ns"
    ip link add acpsdet-h type veth peer name acpsdet-n
    ip link set acpsdet-n netns "$ns"
    ip addr add 198.18.250.1/30 dev acpsdet-h
    ip link set acpsdet-h up
    ip -n "$ns" addr add 198.18.250.2/30 dev acpsdet-n
    ip -n "$ns" link set acpsdet-n up
    ip -n "$ns" link set lo up
    faults+=(cut)
else
    echo "network cut: skipped (needs root and iproute2)"
fi

echo "lease ${lease} s, ${trials} trials; milliseconds from the fault to the line that reports it"
for fault in "${faults[@]}"; do
    times=()
    for i in $(seq 1 "$trials"); do
        times+=("$(trial "$fault" "$i")")
    done
    case $fault in
        kill) what="relay SIGKILLed, learner notices" ;;
        freeze) what="relay SIGSTOPped, learner gives up" ;;
        cut) what="relay's link down, learner gives up" ;;
        learner) what="learner SIGKILLed, relay notices" ;;
    esac
    printf '%-40s %s\n' "$what" "${times[*]}"
done

# What the killed relays and learners left is removed by the next start of any fleet.
"$acps" run grid --sim analytic --runs 1 --episodes 1 --method random --workers 1 -q --out "$work/clean" >/dev/null
