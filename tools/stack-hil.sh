#!/bin/bash
# usage: tools/stack-hil.sh
#   The full simulated stack on real SocketCAN: builds static binaries of crs, motion-core,
#   drive-io, sim-plant (and safety-monitor when its binary exists) and runs
#   `crs sim --platform P --transport vcan --check` for both cabins (P = icosahedron,
#   then helicopter) inside one boot of the vcan QEMU guest (tools/vcan-vm.sh), i.e. every
#   process separately, talking iceoryx2 and CAN. Prints "STACK-HIL: PASS|FAIL".
#   Timing inside the emulator is not real time: the check asserts behaviour (trajectory done,
#   no e-stop, forces in limits, static error), never latency.
# Env: HIL_PROFILE (dev|release, default release: the emulated guest is slow), CRS_VCAN_CACHE.
set -euo pipefail
cd "$(dirname "$0")/.."
PROFILE=${HIL_PROFILE:-release}
TRIPLE=x86_64-unknown-linux-gnu
BINS="crs motion-core drive-io sim-plant can-wire"
[ -f crates/safety-monitor/src/main.rs ] || [ -f crates/safety-monitor/src/bin/safety-monitor.rs ] && BINS="$BINS safety-monitor"
ARGS=(); for b in $BINS; do ARGS+=(--bin "$b"); done
# --workspace: the same feature set in every HIL script, so their builds share all artifacts.
RUSTFLAGS="-C target-feature=+crt-static" cargo build --profile "$PROFILE" --target "$TRIPLE" \
  --workspace "${ARGS[@]}"
DIR=$PROFILE; [ "$PROFILE" = dev ] && DIR=debug
T=${CARGO_TARGET_DIR:-target}/$TRIPLE/$DIR
T=$(cd "$T" && pwd)
EXTRA=""; for b in $BINS; do [ "$b" = crs ] || EXTRA="$EXTRA $T/$b"; done
LOG=$(mktemp); trap 'rm -f "$LOG"' EXIT
# The guest gets config/ and tests/hil/ (the inner tours and the guest script). Its timing is
# the `emulated` profile of crs_supervisor::timing, written by `crs sim --timing emulated` itself
# (TCG cannot run four 1 kHz processes; a 1 ms loop there stalls for up to a second): 4 ms loop
# and SYNC, no SCHED_FIFO/mlockall, watchdogs scaled to match, 0.1 of the demo speed, through
# the inner waypoints of each tour (tests/hil/waypoints-*.csv say why). Everything else
# (platform, plant, limits, the 100 mm check, the --check verdict) is each platform's stack as
# `crs sim --platform` picks it. Timing is asserted on the host only.
start=$(date +%s)
(VCAN_EXTRA_BINS="$EXTRA $T/crs" VCAN_DATA="config tests/hil" VCAN_MEM=${VCAN_MEM:-1024} \
  tools/vcan-vm.sh tests/hil/stack-both.sh) | tee "$LOG" || true
secs=$(( $(date +%s) - start ))
if [ "$(grep -cx 'SIM-CHECK: PASS' "$LOG")" = 2 ] && grep -q '^== crs sim summary (crs-helicopter' "$LOG" &&
  grep -qx 'GUEST_EXIT rc=0' "$LOG"; then
  echo "STACK-HIL: PASS (VM ${secs} s)"
else
  echo "STACK-HIL: FAIL (VM ${secs} s)"; exit 1
fi
