#!/usr/bin/env bash
# Several servers on separate hosts (docs/several-servers.md, issue 13 item 4): three
# hapco-server in three network namespaces and six emulated PHANToMs in a fourth, joined by a
# bridge (one subnet, no multicast: Cyclone's peer list), all on one DDS domain. The clients
# spread over the servers; once every client is being answered, the busiest server is killed
# (SIGKILL: a host gone). Asserts, from the servers' --trace files and the phantoms' per-tick
# CSVs: every client ends on a live server; a client of the killed server takes a force from
# another server at most the safety timeout (50 ms) + 100 ms after the killed server's last
# (the failover, on the device); no pose of any client is stepped by two servers; every rendered
# force is finite, within 7.9 N and within 0.25 N of the tick before. When only the failover
# bound is missed (every other assertion held), the scenario runs once more from the start and
# a second miss fails: on a 2-core host a process that gets no CPU for 100 ms looks dead, and a
# moved client's time then measures the host, not the failover (docs/several-servers.md). The
# clients' logs (moves, resumptions, leases) are printed with any failure. Synchronisation is
# on files the processes write (bounded polls), never on fixed sleeps. Needs root: exit 77 else.
#
# usage: several_servers_test.sh HAPCO_SERVER HAPCO_PHANTOM SOURCE_DIR WORKDIR
set -u
SERVER=$1 PHANTOM=$2 SRC=$3 WORK=$4
SELF=$(readlink -f "$0")  # for the second attempt, after the cd below
PY=/usr/bin/python3
SCENE=$SRC/tests/data/scenes/coarse.txtpb
CLIENTS=6
P=hss$(($$ % 100000))  # namespace prefix of our own
SUBNET=10.79.$(($$ % 200 + 20))
CLIENT_ADDR=$SUBNET.100
DOMAIN=$(($$ % 100 + 120))

[ "$(id -u)" = 0 ] || { echo "SKIP: needs root for network namespaces"; exit 77; }
command -v ip >/dev/null || { echo "SKIP: no iproute2"; exit 77; }
rm -rf "$WORK" && mkdir -p "$WORK" && cd "$WORK" || exit 1

PIDS=()
cleanup() {
  for pid in "${PIDS[@]}"; do kill -KILL "$pid" 2>/dev/null; done
  for ns in "$P-cli" "$P-s1" "$P-s2" "$P-s3"; do
    for pid in $(ip netns pids "$ns" 2>/dev/null); do kill -KILL "$pid" 2>/dev/null; done
    ip netns del "$ns" 2>/dev/null
  done
}
trap cleanup EXIT
FAILS=0
fail() { echo "FAIL: $*"; FAILS=$((FAILS + 1)); }

# --- the hosts: a client namespace with a bridge, a namespace per server on a veth to it ---
if ! ip netns add "$P-cli" 2>"$WORK/netns.err"; then
  echo "SKIP: cannot create network namespaces: $(cat "$WORK/netns.err")"; exit 77
fi
ip -n "$P-cli" link set lo up
ip -n "$P-cli" link add br0 type bridge || { echo "SKIP: no bridge support"; exit 77; }
ip -n "$P-cli" addr add "$CLIENT_ADDR/24" dev br0
ip -n "$P-cli" link set br0 up
PEERS="<Peer address=\"$CLIENT_ADDR\"/>"
for k in 1 2 3; do
  ns=$P-s$k
  ip netns add "$ns" || exit 1
  ip -n "$ns" link set lo up
  ip link add "$P-v$k" netns "$ns" type veth peer name "$P-b$k" netns "$P-cli" || exit 1
  ip -n "$ns" addr add "$SUBNET.$k/24" dev "$P-v$k"
  ip -n "$ns" link set "$P-v$k" up
  ip -n "$P-cli" link set "$P-b$k" master br0
  ip -n "$P-cli" link set "$P-b$k" up
  PEERS="$PEERS<Peer address=\"$SUBNET.$k\"/>"
done
cyclone_config() {  # interface
  cat <<EOF
<?xml version="1.0" encoding="UTF-8" ?>
<CycloneDDS xmlns="https://cdds.io/config"><Domain id="any">
  <General><Interfaces><NetworkInterface name="$1"/></Interfaces><AllowMulticast>false</AllowMulticast></General>
  <Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>60</MaxAutoParticipantIndex>
    <Peers>$PEERS</Peers></Discovery>
</Domain></CycloneDDS>
EOF
}
cyclone_config br0 >"$WORK/cyclone-cli.xml"
for k in 1 2 3; do cyclone_config "$P-v$k" >"$WORK/cyclone-s$k.xml"; done
# The path through the bridge, proven before DDS: a UDP echo in the client host answers
# each server host (bounded: 5 s per host).
ip netns exec "$P-cli" $PY -c '
import socket, sys
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.bind((sys.argv[1], 47001))
s.settimeout(20)
for _ in range(3):
    data, peer = s.recvfrom(64)
    s.sendto(data, peer)
' "$CLIENT_ADDR" &
ECHO_PID=$!
for k in 1 2 3; do
  ip netns exec "$P-s$k" $PY -c '
import socket, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.settimeout(0.2)
deadline = time.monotonic() + 5
while time.monotonic() < deadline:
    s.sendto(b"hapco", (sys.argv[1], 47001))
    try:
        if s.recv(64) == b"hapco":
            sys.exit(0)
    except socket.timeout:
        pass
sys.exit(1)
' "$CLIENT_ADDR" || { fail "s$k cannot reach the client host through the bridge"; exit 1; }
done
wait "$ECHO_PID" 2>/dev/null

# --- three servers, six clients ---
for k in 1 2 3; do
  ip netns exec "$P-s$k" env CYCLONEDDS_URI="file://$WORK/cyclone-s$k.xml" \
    "$SERVER" "$SCENE" --domain "$DOMAIN" --server-id "s$k" --threads 1 --trace "$WORK/trace-s$k.csv" \
    >"$WORK/server-s$k.out" 2>"$WORK/server-s$k.err" &
  PIDS+=($!)
  SERVER_PID[$k]=$!
done
# The servers are up before the clients (as deployed): their ready lines.
for k in 1 2 3; do
  for _ in $(seq 1 600); do grep -q "ready in" "$WORK/server-s$k.out" 2>/dev/null && break; sleep 0.1; done
  grep -q "ready in" "$WORK/server-s$k.out" || { fail "server s$k not ready within 60 s: $(tail -2 "$WORK/server-s$k.err")"; exit 1; }
done
cat >"$WORK/press.csv" <<EOF
x_m,y_m,z_m
EOF
for k in $(seq 1 30); do echo "0,0,$(awk -v k="$k" 'BEGIN{printf "%.6f", -1e-4 * k}')" >>"$WORK/press.csv"; done
CLIENT_PIDS=()
for k in $(seq 1 $CLIENTS); do
  ip netns exec "$P-cli" env CYCLONEDDS_URI="file://$WORK/cyclone-cli.xml" \
    "$PHANTOM" "$SCENE" --client-id "phantom-$k" --domain "$DOMAIN" --trajectory "$WORK/press.csv" \
    --duration-s 8 --force-timeout-ms 50 --csv "$WORK/phantom-$k.csv" --connect-timeout-s 60 \
    >"$WORK/phantom-$k.out" 2>"$WORK/phantom-$k.err" &
  PIDS+=($!)
  CLIENT_PIDS+=($!)
done

# --- wait until every client has 1000 poses stepped (the servers' traces), then kill ---
served() {  # prints "client server count" for every client in the traces
  cat "$WORK"/trace-s*.csv 2>/dev/null | awk -F, '$1 != "client_id" && NF >= 2 {n[$1]++} END {for (c in n) print c, n[c]}'
}
ready=0
for _ in $(seq 1 900); do  # at most 90 s
  if [ "$(served | awk '$2 >= 1000' | wc -l)" -ge "$CLIENTS" ]; then ready=1; break; fi
  sleep 0.1
done
[ "$ready" = 1 ] || { fail "not every client was served within 90 s"; served; tail -3 "$WORK"/*.err; exit 1; }
BUSIEST=$(for k in 1 2 3; do echo "$(awk -F, '$1 != "client_id" {print $1}' "$WORK/trace-s$k.csv" | sort -u | wc -l) s$k"; done |
          sort -rn | head -1 | awk '{print $2}')
echo "clients per server before the kill: $(for k in 1 2 3; do echo -n "s$k $(awk -F, '$1 != "client_id" {print $1}' "$WORK/trace-s$k.csv" | sort -u | wc -l) "; done)"
KILLED_PID=${SERVER_PID[${BUSIEST#s}]}
kill -KILL "$KILLED_PID"
echo "killed $BUSIEST"

# --- every phantom ends by itself (8 s) ---
for pid in "${CLIENT_PIDS[@]}"; do
  wait "$pid" || fail "a phantom exited with $?"
done
for k in 1 2 3; do [ "s$k" = "$BUSIEST" ] || kill -INT "${SERVER_PID[$k]}" 2>/dev/null; done
for k in 1 2 3; do [ "s$k" = "$BUSIEST" ] || wait "${SERVER_PID[$k]}"; done

# --- assertions ---
for k in $(seq 1 $CLIENTS); do
  grep -q "served by '$BUSIEST' at the end" "$WORK/phantom-$k.out" && fail "phantom-$k still on the killed $BUSIEST"
  grep -q "served by 's" "$WORK/phantom-$k.out" || fail "phantom-$k: no server at the end: $(tail -2 "$WORK/phantom-$k.out")"
done
PY_RC=0
$PY - "$WORK" "$CLIENTS" "$BUSIEST" <<'PYEOF' || PY_RC=$?
import csv, glob, math, os, sys
work, clients, killed = sys.argv[1], int(sys.argv[2]), sys.argv[3]
bad, slow = 0, 0
# No pose stepped by two servers (the killed server's trace may end in a partial line).
stepped = {}
for path in sorted(glob.glob(os.path.join(work, "trace-s*.csv"))):
    server = os.path.basename(path)[6:-4]
    with open(path) as f:
        for row in csv.reader(f):
            if len(row) < 9 or row[0] == "client_id":
                continue
            key = (row[0], row[1])
            if key in stepped and stepped[key] != server:
                print(f"FAIL: {row[0]} pose {row[1]} stepped by {stepped[key]} and {server}")
                bad += 1
            stepped[key] = server
by_client = {}
for (client, _), server in stepped.items():
    by_client.setdefault(client, set()).add(server)
print("servers per client:", {c: sorted(s) for c, s in sorted(by_client.items())})
for k in range(1, clients + 1):
    name = f"phantom-{k}"
    ticks = {}
    with open(os.path.join(work, name + ".csv")) as f:
        for r in csv.DictReader(f):
            t = int(r["tick"])
            seq = int(r["force_sequence"])
            prev = ticks.get(t)
            if prev is None or seq > prev[1]:
                ticks[t] = (float(r["time_s"]), seq, (float(r["fx_n"]), float(r["fy_n"]), float(r["fz_n"])))
    order = sorted(ticks)
    if len(order) < 5000:
        print(f"FAIL: {name} ran {len(order)} ticks"); bad += 1; continue
    last, last_time = None, 0.0
    for t in order:
        f = ticks[t][2]
        if not all(math.isfinite(c) for c in f) or math.sqrt(sum(c * c for c in f)) > 7.9 + 1e-12:
            print(f"FAIL: {name} tick {t} renders {f}"); bad += 1; break
        # 250 N/s: 0.25 N per 1 ms tick, more across a late tick during a timeout ramp.
        if last is not None:
            change = math.sqrt(sum((a - b) ** 2 for a, b in zip(f, last)))
            allowed = max(0.25, 250.0 * (ticks[t][0] - last_time))
            if change > allowed + 5e-4:  # time_s has 1 us resolution: 250 N/s x 2 us
                print(f"FAIL: {name} tick {t} changes by {change:.3f} N (limit {allowed:.3f})"); bad += 1; break
        last, last_time = f, ticks[t][0]
    # The longest run of ticks without a new force, after the first force (printed: a live
    # server's stall on a loaded host shows here too, and moves a client by the same rules).
    gap, run_start, first = 0.0, None, False
    for t in order:
        time_s, seq, _ = ticks[t]
        if seq >= 0:
            if first and run_start is not None:
                gap = max(gap, time_s - run_start)
            first, run_start = True, time_s
    # The failover, on the device: from the tick that took the killed server's last force to
    # the first tick that took another server's (forces matched to the servers' traces).
    last_killed, resumed = None, None
    for t in order:
        time_s, seq, _ = ticks[t]
        if seq < 0:
            continue
        server = stepped.get((name, str(seq)))
        if server == killed:
            last_killed, resumed = time_s, None
        elif server is not None and last_killed is not None and resumed is None:
            resumed = time_s
    line = f"{name}: servers {sorted(by_client.get(name, set()))}, longest time without a force {gap * 1e3:.1f} ms"
    if last_killed is not None and resumed is not None:
        failover = resumed - last_killed
        print(f"{line}, failover {failover * 1e3:.1f} ms (last force of {killed} at {last_killed:.3f} s)")
        if failover > 0.050 + 0.100:
            print(f"TIMING: {name} waited {failover * 1e3:.1f} ms for its new server (limit 150 ms)")
            slow += 1
    else:
        print(line)
        if last_killed is not None:
            print(f"FAIL: {name} had no force from another server after {killed}'s last at {last_killed:.3f} s"); bad += 1
if not any(killed in s for s in by_client.values()):
    print(f"FAIL: no client was on {killed}"); bad += 1
if not any(len(s) > 1 and killed in s for s in by_client.values()):
    print(f"FAIL: no client moved away from {killed}"); bad += 1
# 1: a correctness failure; 3: only the failover took longer than its bound.
sys.exit(1 if bad else 3 if slow else 0)
PYEOF
# What each client logged about its server (moves, timeouts, resumptions): says which phase
# took the time when a bound is missed.
client_logs() {
  for k in $(seq 1 $CLIENTS); do
    grep -h "moving from\|no force for\|forces resumed\|no other server" "$WORK/phantom-$k.err" 2>/dev/null | sed "s/^/  /"
    grep -h "served by" "$WORK/phantom-$k.out" 2>/dev/null | sed "s/^ */  phantom-$k: /"
  done
}
if [ "$PY_RC" = 3 ] && [ "$FAILS" = 0 ] && [ "${HAPCO_SEVERAL_SERVERS_ATTEMPT:-1}" = 1 ]; then
  # Only the failover bound was missed, every other assertion held: a host too busy for the
  # bound this once (a stalled client or server process looks like a dead one; the load test
  # docs/several-servers.md measures how often) or a slower failover. The scenario runs once
  # more from the start; a second miss fails. Both attempts' numbers are printed.
  echo "--- client logs of attempt 1"; client_logs
  echo "several_servers: the failover bound was missed on attempt 1 (load: $(cut -d' ' -f1-3 /proc/loadavg)); once more"
  cleanup
  trap - EXIT
  rm -rf "$WORK.attempt1" && mv "$WORK" "$WORK.attempt1"
  HAPCO_SEVERAL_SERVERS_ATTEMPT=2 exec bash "$SELF" "$SERVER" "$PHANTOM" "$SRC" "$WORK"
fi
[ "$PY_RC" != 0 ] && FAILS=$((FAILS + 1))
if [ "$FAILS" != 0 ]; then
  echo "--- client logs"; client_logs
  for k in 1 2 3; do echo "--- server s$k"; tail -3 "$WORK/server-s$k.err"; done
  echo "several_servers: $FAILS failure(s) (load: $(cut -d' ' -f1-3 /proc/loadavg))"; exit 1
fi
echo "several_servers: passed (attempt ${HAPCO_SEVERAL_SERVERS_ATTEMPT:-1})"
