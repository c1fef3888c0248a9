#!/bin/sh
# Runs inside the vcan guest (tools/hil-run.sh): the drive adapter's HIL scenarios on the wire
# model over real vcan. The rig has two CAN interfaces; per scenario each interface is a bus of
# the can-wire hub with two vcan ports, one for drive-io and one for the winch emulator, and
# the hub forwards every frame between them with the bus's bit time and arbitration.
set -u
N=5                      # scenarios (drive_rig::hil::run_all)
args=""; buses=""
for s in $(seq 0 $((N - 1))); do
  dio=""; emu=""
  for b in 0 1; do
    for who in d e; do
      ip link add dev "h${s}b${b}${who}" type vcan && ip link set up "h${s}b${b}${who}" \
        || { echo "HIL_RESULT FAIL (vcan h${s}b${b}${who})"; exit 1; }
    done
    dio="${dio:+$dio,}socketcan:h${s}b${b}d"; emu="${emu:+$emu,}socketcan:h${s}b${b}e"
    buses="$buses --bus name=s${s}b${b},bitrate=1000000,queue=100,ports=h${s}b${b}d+h${s}b${b}e"
  done
  args="$args dio=$dio;emu=$emu"
done
# The hub: SCHED_FIFO in the guest (as the stand-in for the wire it must not fall behind).
can-wire $buses --stats /tmp/wire.json --ready-file /tmp/wire.ready > /tmp/can-wire.log 2>&1 &
hub=$!
i=0; while [ ! -e /tmp/wire.ready ]; do
  i=$((i + 1)); [ $i -gt 2000 ] && { cat /tmp/can-wire.log; echo "HIL_RESULT FAIL (hub)"; exit 1; }
  kill -0 $hub 2>/dev/null || { cat /tmp/can-wire.log; echo "HIL_RESULT FAIL (hub exited)"; exit 1; }
  sleep 0.01
done
# shellcheck disable=SC2086
drive-io-hil $args; rc=$?
kill -TERM $hub; wait $hub
echo "== wire statistics"; cat /tmp/wire.json | tr -d '\n' | cut -c1-400; echo
exit $rc
