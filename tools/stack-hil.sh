#!/bin/bash
# usage: tools/stack-hil.sh
#   The full simulated stack on real SocketCAN: builds static binaries of crs, motion-core,
#   drive-io, sim-plant (and safety-monitor when its binary exists) and runs
#   `crs sim --transport socketcan:vcan0 --check` inside the vcan QEMU guest (tools/vcan-vm.sh),
#   i.e. every process separately, talking iceoryx2 and CAN. Prints "STACK-HIL: PASS|FAIL".
#   Timing inside the emulator is not real time: the check asserts behaviour (trajectory done,
#   no e-stop, forces in limits, static error), never latency.
# Env: HIL_PROFILE (dev|release, default release: the emulated guest is slow), CRS_VCAN_CACHE.
set -euo pipefail
cd "$(dirname "$0")/.."
PROFILE=${HIL_PROFILE:-release}
TRIPLE=x86_64-unknown-linux-gnu
BINS="crs motion-core drive-io sim-plant"
[ -f crates/safety-monitor/src/main.rs ] || [ -f crates/safety-monitor/src/bin/safety-monitor.rs ] && BINS="$BINS safety-monitor"
ARGS=(); for b in $BINS; do ARGS+=(--bin "$b"); done
RUSTFLAGS="-C target-feature=+crt-static" cargo build --profile "$PROFILE" --target "$TRIPLE" \
  -p crs -p motion-core -p drive-io -p sim-plant $( [[ $BINS == *safety-monitor* ]] && echo -p safety-monitor ) "${ARGS[@]}"
DIR=$PROFILE; [ "$PROFILE" = dev ] && DIR=debug
T=${CARGO_TARGET_DIR:-target}/$TRIPLE/$DIR
EXTRA=""; for b in $BINS; do [ "$b" = crs ] || EXTRA="$EXTRA $T/$b"; done
LOG=$(mktemp); trap 'rm -f "$LOG"' EXIT
start=$(date +%s)
VCAN_EXTRA_BINS="$EXTRA" VCAN_DATA="config" VCAN_MEM=${VCAN_MEM:-1024} \
  tools/vcan-vm.sh "$T/crs" sim --transport socketcan:vcan0 --bin-dir /bin --out /tmp/sim \
  --check --timeout-s 400 | tee "$LOG" || true
secs=$(( $(date +%s) - start ))
if grep -qx 'SIM-CHECK: PASS' "$LOG" && grep -qx 'GUEST_EXIT rc=0' "$LOG"; then
  echo "STACK-HIL: PASS (VM ${secs} s)"
else
  echo "STACK-HIL: FAIL (VM ${secs} s)"; exit 1
fi
