#!/bin/bash
# usage: tools/hil-run.sh
#   Builds the static HIL test binary (drive-io-hil) and the wire hub (can-wire) and runs the
#   drive adapter's scenarios inside the vcan QEMU guest (tools/vcan-vm.sh): drive-io + the
#   winch emulator on real SocketCAN, two interfaces per scenario, each a bus of the wire model
#   (tests/hil/drive-hil-guest.sh: a vcan port per node, the hub forwarding with bit time and
#   arbitration). Prints "HIL-VCAN: PASS" or "HIL-VCAN: FAIL"; exit status 0 iff PASS.
# Env: HIL_PROFILE (dev|release, default dev), CRS_VCAN_CACHE (kernel cache, see vcan-vm.sh),
#      CARGO_TARGET_DIR (default <repo>/target).
set -euo pipefail
cd "$(dirname "$0")/.."
PROFILE=${HIL_PROFILE:-dev}
TRIPLE=x86_64-unknown-linux-gnu
# --target keeps build scripts/proc-macros dynamic while the test binary is static glibc.
# --workspace: the same feature set in every HIL script, so their builds share all artifacts.
RUSTFLAGS="-C target-feature=+crt-static" cargo build --profile "$PROFILE" --target "$TRIPLE" \
  --workspace --bin drive-io-hil --bin can-wire
DIR=$PROFILE; [ "$PROFILE" = dev ] && DIR=debug
T=${CARGO_TARGET_DIR:-target}/$TRIPLE/$DIR
T=$(cd "$T" && pwd)
LOG=$(mktemp); trap 'rm -f "$LOG"' EXIT
start=$(date +%s)
(VCAN_EXTRA_BINS="$T/drive-io-hil $T/can-wire" tools/vcan-vm.sh tests/hil/drive-hil-guest.sh) \
  | tee "$LOG" || true
secs=$(( $(date +%s) - start ))
if grep -qx 'HIL_RESULT PASS' "$LOG" && grep -qx 'GUEST_EXIT rc=0' "$LOG"; then
  echo "HIL-VCAN: PASS ($(grep -c '^HIL PASS' "$LOG") scenarios, VM ${secs} s)"
else
  echo "HIL-VCAN: FAIL (VM ${secs} s; see HIL FAIL lines above)"; exit 1
fi
