#!/usr/bin/env bash
# scripts/loadtest-capacity's sweep rule, with stand-ins for hapco-server and hapco-loadtest
# (no DDS, no timing): an N that loses more than 1 % of its ticks is run once more and the
# second run decides. Scripted losses: N = 4 fails once (a stall of the host), N = 6 fails
# twice (the limit). Expected: capacity 4, both runs of N = 4 and of N = 6 in the CSV (column
# attempt), N = 8 never tried. Then --floor-only: the floor's rows alone. Usage:
# capacity_sweep_test.sh SOURCE_DIR WORK_DIR
set -u
SRC=$1
WORK=$2
rm -rf "$WORK"; mkdir -p "$WORK/build/bin"

# hapco-server stand-in: says it is ready, then waits to be stopped.
cat >"$WORK/build/bin/hapco-server" <<'EOF'
#!/usr/bin/env bash
echo "hapco-server: ready, 2 stepping thread(s)"
trap 'exit 0' INT TERM
while :; do sleep 0.05; done
EOF
# hapco-loadtest stand-in: the loss for (N, attempt) comes from FAKE_LOST ("N:attempt=pct ..."),
# 0.1 % otherwise; the attempt is counted per N in a file beside the runs.
cat >"$WORK/build/bin/hapco-loadtest" <<'EOF'
#!/usr/bin/env bash
N=; OUT=
while [ $# -gt 0 ]; do
  case $1 in --clients) N=$2; shift ;; --csv-dir) OUT=$2; shift ;; esac
  shift
done
COUNT="$FAKE_STATE/n$N"
ATTEMPT=$(( $(cat "$COUNT" 2>/dev/null || echo 0) + 1 )); echo "$ATTEMPT" >"$COUNT"
LOST=0.1
for entry in $FAKE_LOST; do
  [ "${entry%%=*}" = "$N:$ATTEMPT" ] && LOST=${entry#*=}
done
mkdir -p "$OUT"
{
  echo "client,clients,lost_pct,missed_pct,rt_p50_us,rt_p99_us,rt_p999_us,server_step_p99_us,server_cpu,server_physics_us,server_model_us,server_force_write_us,server_frame_us"
  echo "all,$N,$LOST,$LOST,100,200,300,50,0.5,10,1,5,1"
} >"$OUT/summary.csv"
echo "client,round_trip_us" >"$OUT/roundtrip.csv"
EOF
chmod +x "$WORK/build/bin/hapco-server" "$WORK/build/bin/hapco-loadtest"
mkdir -p "$WORK/state"

FAKE_STATE="$WORK/state" FAKE_LOST="4:1=2.5 6:1=3.0 6:2=4.0" \
  "$SRC/scripts/loadtest-capacity" --build "$WORK/build" --no-floor --duration-s 1 --steps "1 2 4 6 8" \
  --min-clients 1 --rt-priority 0 --runs-dir "$WORK/runs" --data "$WORK/capacity.csv" --figures "$WORK/capacity" \
  >"$WORK/out.txt" 2>"$WORK/err.txt"
RC=$?
bad=0
fail() { echo "FAIL: $*"; bad=1; }
[ "$RC" = 0 ] || fail "loadtest-capacity exited $RC: $(tail -3 "$WORK/err.txt")"
grep -q "^capacity: 4 clients" "$WORK/out.txt" || fail "expected 'capacity: 4 clients', got: $(grep '^capacity' "$WORK/out.txt")"
grep -q "N = 4 lost 2.5 % - running it once more" "$WORK/err.txt" || fail "N = 4 was not run again after its failed run"
# The CSV: N = 4 and N = 6 twice (attempts 1 and 2), N = 1 and 2 once, N = 8 never.
rows=$(awk -F, 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next} {printf "%s/%s ", $c["clients"], $c["attempt"]}' "$WORK/capacity.csv")
[ "$rows" = "1/1 2/1 4/1 4/2 6/1 6/2 " ] || fail "CSV rows (clients/attempt): '$rows', expected '1/1 2/1 4/1 4/2 6/1 6/2 '"
[ "$(cat "$WORK/state/n8" 2>/dev/null || echo 0)" = 0 ] || fail "N = 8 was tried after N = 6 failed twice"

# --floor-only: the floor's sweep alone (same rule), no HapCo rows, its own summary line.
rm -rf "$WORK/state"; mkdir -p "$WORK/state"
FAKE_STATE="$WORK/state" FAKE_LOST="2:1=1.5 4:1=2.0 4:2=3.0" \
  "$SRC/scripts/loadtest-capacity" --build "$WORK/build" --floor-only --duration-s 1 --steps "1 2 4 6" \
  --min-clients 1 --rt-priority 0 --runs-dir "$WORK/runs-floor" --data "$WORK/floor.csv" --figures "$WORK/floor" \
  >"$WORK/floor-out.txt" 2>"$WORK/floor-err.txt"
RC=$?
[ "$RC" = 0 ] || fail "--floor-only exited $RC: $(tail -3 "$WORK/floor-err.txt")"
grep -q "^floor: *2 clients" "$WORK/floor-out.txt" || fail "expected 'floor: 2 clients', got: $(cat "$WORK/floor-out.txt")"
grep -q "^capacity:" "$WORK/floor-out.txt" && fail "--floor-only printed a HapCo capacity"
servers=$(awk -F, 'NR==1{for(i=1;i<=NF;i++)c[$i]=i; next} {printf "%s ", $c["server"]}' "$WORK/floor.csv")
[ "$servers" = "floor floor floor floor floor " ] || fail "--floor-only rows by server: '$servers'"
# Refused combinations name what to leave out.
"$SRC/scripts/loadtest-capacity" --build "$WORK/build" --floor-only --physics-every 8 --runs-dir "$WORK/runs-x" \
  --data "$WORK/x.csv" --figures "$WORK/x" >/dev/null 2>"$WORK/refused.txt" && fail "--floor-only --physics-every ran"
grep -q "leave out --security and --physics-every" "$WORK/refused.txt" || fail "refusal says: $(cat "$WORK/refused.txt")"
[ "$bad" = 0 ] && echo "ok: capacity 4, a single failed run retried, the limit confirmed by two; --floor-only"
exit "$bad"
