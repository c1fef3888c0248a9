#!/bin/bash
# usage: tools/wire-hil.sh
#   The wire model's vcan forwarding on a real kernel: builds static can-wire and can-wire-hil
#   and runs them inside the vcan QEMU guest (tools/vcan-vm.sh). The guest script
#   (tests/hil/wire-guest.sh) adds vcan10..vcan12; can-wire-hil starts the hub with one bus over
#   them and checks behaviour only (guest time is emulated): forwarding to every other node,
#   one order for all receivers, a burst beyond the queue dropped and counted, error frames
#   passed through, the final statistics; and SocketCAN's transmit echo on vcan0.
#   Prints "WIRE-HIL: PASS|FAIL"; exit status 0 iff PASS.
# Env: HIL_PROFILE (dev|release, default dev), CRS_VCAN_CACHE (kernel cache, see vcan-vm.sh),
#      CARGO_TARGET_DIR (default <repo>/target).
set -euo pipefail
cd "$(dirname "$0")/.."
PROFILE=${HIL_PROFILE:-dev}
TRIPLE=x86_64-unknown-linux-gnu
# --workspace: the same feature set in every HIL script, so their builds share all artifacts.
RUSTFLAGS="-C target-feature=+crt-static" cargo build --profile "$PROFILE" --target "$TRIPLE" \
  --workspace --bin can-wire --bin can-wire-hil
DIR=$PROFILE; [ "$PROFILE" = dev ] && DIR=debug
T=${CARGO_TARGET_DIR:-target}/$TRIPLE/$DIR
T=$(cd "$T" && pwd)
LOG=$(mktemp); trap 'rm -f "$LOG"' EXIT
start=$(date +%s)
(VCAN_EXTRA_BINS="$T/can-wire $T/can-wire-hil" tools/vcan-vm.sh tests/hil/wire-guest.sh) \
  | tee "$LOG" || true
secs=$(( $(date +%s) - start ))
if grep -qx 'WIRE_RESULT PASS' "$LOG" && grep -qx 'GUEST_EXIT rc=0' "$LOG"; then
  echo "WIRE-HIL: PASS ($(grep -c '^WIRE-HIL PASS' "$LOG") checks, VM ${secs} s)"
else
  echo "WIRE-HIL: FAIL (VM ${secs} s; see WIRE-HIL FAIL lines above)"; exit 1
fi
