#!/bin/bash
# The systemd boot test's guest side (tools/systemd-boot-test.sh boots it; runs as root from
# crs-boot-test.service after multi-user.target). One "BOOT-CHECK: ok|FAIL <what>" line per
# check, then "BOOT-TEST: PASS|FAIL". Behaviour only: the guest is emulated (TCG), nothing here
# asserts timing; every wait is on a condition, bounded so a hang fails instead of blocking.
set -u
T=/crs-test
FAILS=0
up() { cut -d' ' -f1 /proc/uptime; }
ok() { echo "BOOT-CHECK: ok $* [$(up) s]"; }
bad() { echo "BOOT-CHECK: FAIL $* [$(up) s]"; FAILS=$((FAILS + 1)); }
check() { local what=$1; shift; if "$@"; then ok "$what"; else bad "$what"; fi; }
# wait_for SECONDS CMD...: polls CMD until it succeeds; false once SECONDS have passed.
wait_for() {
  local end=$(($(cut -d. -f1 /proc/uptime) + $1)); shift
  while ! "$@"; do [ "$(cut -d. -f1 /proc/uptime)" -lt $end ] || return 1; sleep 0.5; done
}
# The journal's error and warning lines of the stack's units (a CI log shows why a check failed).
journal_why() {
  echo "== journalctl -p warning of the stack's units (failure context)"
  journalctl -b -p warning --no-pager -q -o short-monotonic -u 'crs-*' |
    grep -v 'heartbeat lost\|overran' | tail -n 60 | sed 's/^/BOOT:   journal: /'
  local first
  first=$(journalctl -b -p err --no-pager -q -o short-monotonic -u 'crs-*' | head -n 1)
  [ -n "$first" ] || return 0
  # The cause often sits in the lines before the first error (info/notice) and in the error
  # entries' structured fields (drive-io's state, code, node), which -o short does not show.
  echo "== the stack's journal up to its first error line (every priority)"
  journalctl -b --no-pager -q -o short-monotonic -u 'crs-*' | grep -F -B 30 -m 1 -- "$first" |
    sed 's/^/BOOT:   before: /'
  echo "== the first error entries with their fields"
  journalctl -b -p err --no-pager -q -o verbose -u 'crs-*' | grep -vE '^ +_|^ +(SYSLOG_|CODE_|INVOCATION_ID|TARGET|SPAN)' |
    head -n 40 | sed 's/^/BOOT:   fields: /'
}
finish() {
  if [ $FAILS -eq 0 ]; then echo "BOOT-TEST: PASS"; else
    journal_why
    echo "== journal of the stack, last 80 lines"
    journalctl -b --no-pager -o short-monotonic -u 'crs-*' | tail -n 80 | sed 's/^/BOOT:   log: /'
    echo "BOOT-TEST: FAIL ($FAILS checks failed)"
  fi
  sync
  systemctl --force --force poweroff
  exit 0
}
ride() { timeout 30 crs ride "$@"; }
UNITS="crs-isolation crs-sim-plant crs-safety-monitor crs-drive-io crs-motion-core"
DAEMONS="crs-sim-plant crs-safety-monitor crs-drive-io crs-motion-core"
prop() { systemctl show -p "$2" --value "$1.service"; }
echo "BOOT: guest up at $(cut -d' ' -f1 /proc/uptime) s, $(systemctl --version | head -1)"

# --- 1. the package -------------------------------------------------------------------------
V1=$(dpkg-deb -f $T/crs-motion-1.deb Version); V2=$(dpkg-deb -f $T/crs-motion-2.deb Version)
check "dpkg -i crs-motion $V1" dpkg -i $T/crs-motion-1.deb
check "system user crs created by postinst" id crs
check "units installed (systemctl cat crs-stack.target)" systemctl cat crs-stack.target >/dev/null
check "nothing started by the install" test "$(systemctl is-active crs-motion-core.service)" != active
command -v man >/dev/null || echo "BOOT: (no man-db in the guest: pages are checked by tools/deb-test.sh)"
for b in motion-core drive-io safety-monitor sim-plant crs; do
  [ -x /usr/bin/$b ] || bad "/usr/bin/$b installed"
done
[ $FAILS -eq 0 ] || finish

# --- 2. the rig: socketcan per bus in the stack's namespace, simulated drives ---------------
# The real control PC's layout: every bus a SocketCAN interface (here vcan, created inside the
# namespace by crs-isolation.service), the simulated drives (crs-sim-plant.service) as the rig.
# Both are edits of conffiles, which the upgrade below must keep.
sed -i 's#"wire:/run/crs/wire/\([a-z0-9]*\)\.sock"#"socketcan:\1"#' /etc/crs/config/drives.toml
sed -i 's#^CRS_VCAN_CREATE=.*#CRS_VCAN_CREATE="can0 can1 can2 can3 safety"#' /etc/crs/config/can-netns.conf
IFACES=$(sed -n 's/^transport = "socketcan:\(.*\)"/\1/p' /etc/crs/config/drives.toml | tr '\n' ' ')
check "drives.toml edited to socketcan per bus ($IFACES)" test "$(wc -w <<<"$IFACES")" = 5
check "no wire: transport left in drives.toml" bash -c '! grep -q "^transport = \"wire:" /etc/crs/config/drives.toml'
check "systemctl enable crs-sim-plant.service (the rig)" systemctl enable crs-sim-plant.service
# The emulated machine's settings (TCG cannot run 1 ms loops): the `emulated` timing copies of
# the configs (crs timing), no SCHED_FIFO/pinning, longer start and watchdog times. The units'
# other keys (Type=notify, Restart=no, isolation) stay as shipped.
(cd /etc/crs && crs timing emulated --out /etc/crs/emulated) || bad "crs timing emulated"
E=/etc/crs/emulated/timing-emulated
# This guest is slower than the `emulated` profile's guests (tools/stack-hil.sh: one `crs sim`,
# no systemd, journald, dpkg or console beside it): stalls of 300-500 ms were seen here while
# the stack started (all 8 drives' TPDO timeout at once, i.e. drive-io or the simulated drives
# descheduled, then the monitor's trip). So the administrator of this machine widens the
# watchdogs further, in the copies, each within the bound its daemon enforces: drive-io's
# node/TPDO timeout 2 s (the drives' consumer of drive-io's heartbeat follows at 2x), its
# stale-setpoint stop at its 500 ms bound, the safety heartbeat's validation time at its 200 ms
# bound (in both configs: the drives compare the monitor's configuration CRC), and so the pair
# window (SRVT) of the doubled heartbeat (a guest stall between the monitor's two frames of a
# pair, 80 ms, broke the emulated profile's 75 ms window at start), the monitor's silences at
# their ~1 s bound (67 cycles). Checks and limits stay as shipped.
# setkey FILE SECTION KEY VALUE: the key must exist in that section (a renamed key fails).
setkey() {
  awk -v s="$2" -v k="$3" -v v="$4" '
    /^[ \t]*\[/ { cur = $0; gsub(/^[ \t]*\[|\].*$/, "", cur) }
    cur == s && $0 ~ ("^" k "[ \t]*=") { $0 = k " = " v; n++ }
    { print } END { exit n == 0 }' "$1" > "$1.new" && mv "$1.new" "$1" ||
    { rm -f "$1.new"; bad "$1: [$2] $3 not found"; }
}
for kv in "bus heartbeat_timeout_ms 2000" "bus stale_setpoint_cycles 125" \
  "safety_heartbeat validation_time_ms 200" "safety_heartbeat pair_window_ms 200"; do
  setkey $E/drives.toml $kv
done
for kv in "monitor silence_cycles 67" "feedback silence_cycles 67" "forces silence_cycles 67" \
  "can reader_stall_cycles 67" "can safety_io_silence_cycles 67" "can safety_validation_time_ms 200" \
  "can safety_pair_window_ms 200"; do
  setkey $E/safety-monitor.toml $kv
done
grep -n '^heartbeat_timeout_ms\|^stale_setpoint_cycles\|^validation_time_ms\|^pair_window_ms' $E/drives.toml | sed 's/^/BOOT:   drives.toml: /'
IO=/run/crs-test-io
: > $IO; chmod 0644 $IO
ln -sfn /etc/crs/config/plant $E/plant
for u in $DAEMONS; do
  mkdir -p /etc/systemd/system/$u.service.d
  {
    echo "[Service]"
    echo "Environment=CRS_CONFIG_DIR=$E"
    echo "CPUAffinity="
    # The guest's CPUs are saturated once motion-core's loop runs (run 3: the monitor's cycle
    # overran, the simulated safety I/O node missed its heartbeat within 200 ms and removed
    # the drives' torque as motion-core started). The monitor keeps its shipped SCHED_FIFO 70
    # (a 15 ms cycle of little work: it cannot hog a CPU); the other loops run SCHED_OTHER,
    # the simulated drives and I/O node first, all ahead of this test's own processes (nice 10).
    case $u in
      crs-safety-monitor) echo "Nice=-10" ;;
      crs-sim-plant) echo "CPUSchedulingPolicy=other"; echo "CPUSchedulingPriority=0"; echo "Nice=-10" ;;
      *) echo "CPUSchedulingPolicy=other"; echo "CPUSchedulingPriority=0"; echo "Nice=-5" ;;
    esac
    echo "TimeoutStartSec=300s"
    echo "WatchdogSec=30s"
    case $u in
      crs-drive-io) echo "ExecStart="; echo "ExecStart=/usr/bin/drive-io --config config/drives.toml" ;;
      crs-sim-plant) echo "ExecStart="
        # --io-control: the simulated safety I/O node's reset key, turned by this test.
        echo "ExecStart=/usr/bin/sim-plant --plant config/plant/icosahedron.toml --drives config/drives.toml --io-control $IO" ;;
    esac
  } > /etc/systemd/system/$u.service.d/emulated.conf
done
systemctl daemon-reload

# --- 3. the stack under systemd ---------------------------------------------------------------
ERR0=$(journalctl -b -p err --no-pager -q -o cat | wc -l)
t0=$(cut -d' ' -f1 /proc/uptime)
check "systemctl start crs-stack.target" timeout 600 systemctl start crs-stack.target
echo "BOOT: stack started in $(awk -v a="$t0" '{printf "%.0f", $1 - a}' /proc/uptime) s (emulated)"
for u in $UNITS; do check "$u active" test "$(systemctl is-active $u.service)" = active; done
if [ "$(systemctl is-active crs-motion-core.service)" != active ]; then
  for u in $DAEMONS; do
    journalctl -b --no-pager -q -o short-monotonic -u $u.service | grep -v 'heartbeat lost\|overran' | head -n 25 | sed "s/^/BOOT:   $u: /"
  done
  finish
fi
for u in $DAEMONS; do
  check "$u Type=notify (ready by sd_notify)" test "$(prop $u Type)" = notify
  w=$(prop $u WatchdogUSec)
  check "$u watchdog set (WatchdogUSec=$w)" test -n "$w" -a "$w" != 0 -a "$w" != infinity
  check "$u shipped with WatchdogSec= (unit file)" grep -q '^WatchdogSec=' /usr/lib/systemd/system/$u.service
done
MC=$(prop crs-motion-core MainPID)

# --- 4. isolation: impersonation from outside the stack's namespaces is refused --------------
check "can0 exists inside the stack's namespace" ip -n crs link show can0
check "can0 invisible outside it (host namespace)" bash -c '! ip link show can0 2>/dev/null'
as_crs() { setpriv --reuid=crs --regid=crs --clear-groups -- "$@"; }
refused() { ! "$@" >/dev/null 2>&1; }
check "user crs cannot enter the stack's network namespace" refused as_crs nsenter --net=/run/netns/crs true
check "user crs cannot reach the stack's /tmp and /dev/shm" refused as_crs ls /run/crs/private/shm
# iceoryx2 0.10: bookkeeping under /tmp/iceoryx2/, segments in /dev/shm (iox2_*).
iox() { echo "$(find /tmp/iceoryx2 -type f 2>/dev/null | wc -l) $(ls /dev/shm 2>/dev/null | grep -c '^iox2')"; }
read -r f_in s_in < <(nsenter -t "$MC" -m bash -c "$(declare -f iox); iox")
read -r f_out s_out < <(iox)
check "the stack's iceoryx2 files: $f_in + $s_in segments inside its units, $f_out + $s_out outside" \
  test "$f_in" -gt 0 -a "$s_in" -gt 0 -a "$f_out" = 0 -a "$s_out" = 0
# An impostor safety monitor as user crs outside the namespace: it cannot open the buses.
imp=$(cd /etc/crs && CRS_CONFIG_DIR=$E timeout 120 setpriv --reuid=crs --regid=crs --clear-groups -- \
  safety-monitor --config config/safety-monitor.toml 2>&1); rc=$?
echo "$imp" | tail -2 | sed 's/^/BOOT:   impostor: /'
check "an impostor safety-monitor (user crs, outside) cannot open the CAN interfaces (rc=$rc)" \
  bash -c "[ $rc -ne 0 ] && [ $rc -ne 124 ] && grep -qi 'no such device\|can0' <<<\"\$1\"" _ "$imp"

# --- 5. nothing moves until a ride is started ---------------------------------------------------
# The operator console (crs console) inside the stack's namespaces, as a transient unit like
# the stack's: its /api/status has the drives' cable lengths.
# (A unit file, not systemd-run: the guest has no D-Bus.)
cat > /run/systemd/system/crs-test-console.service <<UNIT
[Service]
User=crs
NetworkNamespacePath=/run/netns/crs
BindPaths=/run/crs/private/tmp:/tmp /run/crs/private/shm:/dev/shm
WorkingDirectory=/etc/crs
Environment=CRS_CONFIG_DIR=$E
ExecStart=/usr/bin/crs console --addr 127.0.0.1:8080
Nice=10
UNIT
systemctl daemon-reload
check "the console started in the stack's namespaces" systemctl start crs-test-console.service
status() { timeout 20 ip netns exec crs bash -c 'exec 3<>/dev/tcp/127.0.0.1/8080 || exit 1
  printf "GET /api/status HTTP/1.0\r\nHost: x\r\n\r\n" >&3; cat <&3' 2>/dev/null | tr -d '\r' | sed '1,/^$/d'; }
lengths() { status | grep -o '"cable_length_m":\[[^]]*\]' | sed 's/.*\[//; s/\]//'; }
have_lengths() { [ "$(lengths | tr ',' '\n' | grep -c .)" -ge 8 ]; }
check "drive feedback with 8 cable lengths (console /api/status)" wait_for 240 have_lengths
ride_idle() { ride status 2>/dev/null | grep -q 'idle'; }
ride_settled() { ride status 2>/dev/null | grep -qE 'idle|latched'; }
wait_for 120 ride_settled
ride status | sed 's/^/BOOT:   ride status: /'
START_ERRS=$(journalctl -b -p err --no-pager -q -o short-monotonic -u 'crs-*')
check "no error line while the stack started ($(grep -c . <<<"$START_ERRS"))" test -z "$START_ERRS"
if ride status 2>/dev/null | grep -q latched || [ -n "$START_ERRS" ]; then
  # A trip while the stack starts fails the test (above), with its cause; the rest of the
  # checks still run after the operator's reset (the safety I/O node's key, turned and
  # released), so one run shows every failure.
  echo "BOOT: tripped while starting; the error lines:"
  sed 's/^/BOOT:   err: /' <<<"$START_ERRS" | head -n 20
  journal_why
  for k in 1 2 3; do
    echo "reset_key on" > $IO; sleep 2; : > $IO
    wait_for 30 ride_idle && { echo "BOOT: start-up trip reset by the key (attempt $k)"; break; }
  done
fi
check "motion-core idle and holding (crs ride status)" wait_for 60 ride_idle
ride status | sed 's/^/BOOT:   ride status: /'
ERR0=$(journalctl -b -p err --no-pager -q -o cat | wc -l)
# max |a_i - b_i| over the cables, m
maxdiff() { awk -v a="$1" -v b="$2" 'BEGIN{n=split(a,x,",");split(b,y,",");m=0;for(i=1;i<=n;i++){d=x[i]-y[i];if(d<0)d=-d;if(d>m)m=d};printf "%.6f",m}'; }
L1=$(lengths); sleep 5; L2=$(lengths)
d=$(maxdiff "$L1" "$L2")
check "nothing moves before a ride: cable lengths over 5 s differ by at most $d m (<= 0.0005)" \
  awk -v d="$d" 'BEGIN{exit !(d <= 0.0005)}'

# --- 6. upgrade while the stack runs: edits kept, nothing restarted ---------------------------
declare -A PID
for u in $DAEMONS; do PID[$u]=$(prop $u MainPID); done
check "dpkg -i crs-motion $V2 (upgrade, stack running)" bash -c "dpkg -i $T/crs-motion-2.deb </dev/null"
check "installed version is $V2" test "$(dpkg-query -W -f '${Version}' crs-motion)" = "$V2"
check "the drives.toml edit survived the upgrade" grep -q '^transport = "socketcan:can0"' /etc/crs/config/drives.toml
check "the can-netns.conf edit survived the upgrade" grep -q '^CRS_VCAN_CREATE="can0' /etc/crs/config/can-netns.conf
for u in $DAEMONS; do
  check "$u not restarted by the upgrade (MainPID ${PID[$u]})" test "$(prop $u MainPID)" = "${PID[$u]}"
done

# --- 7. a ride --------------------------------------------------------------------------------
L0=$(lengths)
out=$(ride start $T/ride.csv 2>&1); rc=$?
echo "$out" | sed 's/^/BOOT:   ride start: /'
check "crs ride start accepted" test $rc = 0
riding() { ride status 2>/dev/null | grep -q riding; }
moved() { awk -v d="$(maxdiff "$L0" "$(lengths)")" 'BEGIN{exit !(d > 0.005)}'; }
if [ $rc = 0 ]; then
  check "the ride moves the cables (> 5 mm)" wait_for 120 moved
  check "the ride ends, motion-core idle again" wait_for 600 ride_idle
else
  bad "the ride moves the cables (not started)"
fi
ride status | sed 's/^/BOOT:   ride status: /'
ERR1=$(journalctl -b -p err --no-pager -q -o cat | wc -l)
check "no error line from idle to the end of the ride ($((ERR1 - ERR0)))" test "$ERR1" = "$ERR0"

# --- 8. the monitor killed: the drives stop, one trip, nothing restarts ----------------------
# What the units promise (systemd/README.md, "A unit dies"): motion-core goes with the monitor
# (BindsTo=); drive-io, the simulated drives and the namespace stay up, drive-io trips on the
# missing safety heartbeat, holds the drives in their quick stop and says so; the safety I/O
# node removes their torque (STO); nothing restarts (Restart=no).
ERRK=$(journalctl -b -p err --no-pager -q -o cat | wc -l)
since=$(date '+%Y-%m-%d %H:%M:%S')
check "a second ride started" ride start $T/ride.csv
check "the second ride under way when the monitor is killed" wait_for 60 riding
check "systemctl kill -s KILL crs-safety-monitor" systemctl kill -s KILL crs-safety-monitor.service
gone() { [ "$(systemctl is-active crs-safety-monitor.service)" != active ]; }
check "the monitor stays dead" wait_for 60 gone
mc_stopped() { [ "$(systemctl is-active crs-motion-core.service)" != active ]; }
check "motion-core stopped with it (BindsTo=)" wait_for 60 mc_stopped
trip_line='safety heartbeat invalid or missing: e-stop'
dio_stop() { journalctl -u crs-drive-io.service --since "$since" --no-pager -q -o cat | grep -q "$trip_line"; }
check "drive-io reports the trip (\"$trip_line\")" wait_for 60 dio_stop
for u in crs-drive-io crs-sim-plant crs-isolation; do
  check "$u still active (holding the drives stopped, reporting)" test "$(systemctl is-active $u.service)" = active
done
check "crs-stack.target still active (nothing stopped through it)" test "$(systemctl is-active crs-stack.target)" = active
sleep 2; S1=$(lengths); sleep 3; S2=$(lengths)
d=$(maxdiff "$S1" "$S2")
check "the drives stopped: cable lengths over 3 s differ by at most $d m (<= 0.0005)" \
  awk -v d="$d" 'BEGIN{exit !(d <= 0.0005)}'
ERRS=$(journalctl -b -p err --no-pager -q -o short-monotonic | tail -n +$((ERRK + 1)))
echo "$ERRS" | sed 's/^/BOOT:   err: /'
n_trip=$(grep -c "$trip_line" <<<"$ERRS")
# One event, one error line: drive-io's trip (whether its own validation time ran out first or
# the safety I/O node's STO reached the drives first, which drive-io takes as the same stop);
# the quick stop that follows is logged at warning, nothing else at err.
n_other=$(grep -v "$trip_line" <<<"$ERRS" | grep -c .)
check "exactly one error line after the kill, drive-io's trip ($n_trip trip, $n_other other)" \
  test "$n_trip" = 1 -a "$n_other" = 0
# The trip's reason (Timeout: drive-io's validation time ran out first; Overdue: the drives'
# STO from the safety I/O node reached drive-io first, under the overdue heartbeat).
journalctl -u crs-drive-io.service --since "$since" --no-pager -q -o verbose -p err |
  grep -E '^ +F_REASON=' | head -n 2 | sed 's/^ */BOOT:   drive-io trip: /'
journalctl -u crs-drive-io.service --since "$since" --no-pager -q -o cat -p warning |
  grep -v 'overran' | head -n 5 | sed 's/^/BOOT:   drive-io after the kill: /'
for u in $DAEMONS; do check "$u NRestarts=0" test "$(prop $u NRestarts)" = 0; done
check "the monitor not restarted (Restart=no)" test "$(systemctl is-active crs-safety-monitor.service)" != active

# --- 9. a clean stop ------------------------------------------------------------------------
systemctl stop crs-test-console.service
since=$(date '+%Y-%m-%d %H:%M:%S')
check "systemctl stop crs-stack.target" timeout 120 systemctl stop crs-stack.target
# `systemctl stop` waits for the target's own stop job only, and the target (After= its units)
# stops first: the units' stop jobs (PartOf=) run on after it returns, the simulated drives
# after drive-io and the monitor, the namespace last. Wait for them, bounded.
inactive() { [ "$(systemctl is-active "$1.service")" != active ] && [ "$(systemctl is-active "$1.service")" != deactivating ]; }
for u in $UNITS; do check "$u not active after the stop" wait_for 60 inactive $u; done
no_netns() { [ ! -e /run/netns/crs ]; }
check "the stack's network namespace removed" wait_for 60 no_netns
ERRS=$(journalctl -b -p err --since "$since" --no-pager -q -o cat)
check "no error line from the stop ($(grep -c . <<<"$ERRS"))" test -z "$ERRS"
finish
