#!/usr/bin/env bash
# CANopen interoperability against python `canopen` + python-can (a CANopen stack not written
# here), on the host over python-can's udp_multicast bus, which can-transport
# speaks as `pycan-udp:GROUP:PORT` (the QEMU guest has no python):
#  (a) drive-io configures (SDO script from config/eds/crs-winch.eds, read-back, DCF) and runs
#      python canopen LocalNode drives made from the same EDS: NMT, SDO, SYNC, PDOs, quick stop,
#      EMCY, heartbeat loss, a drive rebooting mid-run, a drive refusing an object;
#  (b) a python canopen master (RemoteNodes) configures and drives the project's winch-emulator:
#      SDO + aborts, its own PDO mapping, CiA 402 enable, motion, quick stop, EMCY (following
#      error), heartbeat loss at the drive;
#  (a2) the same with vendor-like drives (config/eds/vendor-csp-drive.eds: minimal event-driven
#      PDOs, stray PDOs enabled, CompactSubObj, a segmented device name and string parameter, no
#      force object) whose forces come from python canopen CiA 404 load cells
#      (config/eds/crs-load-cell.eds), their identity checked at boot; a swapped drive refused;
#  (c) python canopen imports the DCFs drive-io wrote, and Lely's dcfchk (pip dcf-tools)
#      accepts every one of them.
# (python-can reading the stack's candump logs is in tools/ecosystem-test.sh.)
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -c "import canopen, can, msgpack" 2>/dev/null || pip install -q canopen python-can msgpack >/dev/null
command -v dcfchk >/dev/null || pip install -q dcf-tools >/dev/null
cargo build -q -p drive-rig --bin drive-io-interop --bin winch-emulator
BIN=${CARGO_TARGET_DIR:-target}/debug
OUT=out/canopen-interop
rm -rf "$OUT"; mkdir -p "$OUT"
GROUP=239.74.163.20
PORT=$((44000 + $$ % 1000))
PIDS=()
cleanup() { for p in "${PIDS[@]:-}"; do [ -n "$p" ] && kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
FAIL=0

drives() { # scenario port extra-args...
  local sc=$1 port=$2; shift 2
  python3 tools/canopen_interop.py drive --group $GROUP --port "$port" --drives 2 --scenario "$sc" \
    --node 2 --after 0.5 --seconds 30 "$@" > "$OUT/drives-$sc${LOGSUFFIX:-}.log" 2>&1 &
  PIDS+=($!)
  sleep 1.5 # python canopen up before drive-io sends its NMT reset
}

echo "-- (a) drive-io configures and runs python canopen LocalNode drives"
n=0
for sc in run emcy heartbeat reboot refused; do
  port=$((PORT + n)); n=$((n + 1))
  extra=()
  if [ "$sc" = refused ]; then
    # The drives lack 0x6065 (following error window) that drive-io's EDS lists.
    sed 's/^\[6065\]/[2065]/' config/eds/crs-winch.eds > "$OUT/no-6065.eds"
    extra=(--eds "$OUT/no-6065.eds")
  fi
  drives "$sc" "$port" "${extra[@]}"
  args=(--transport "pycan-udp:$GROUP:$port" --scenario "$sc" --drives 2 --node 2 --code 0x2310)
  [ "$sc" = run ] && args+=(--dcf-dir "$OUT/dcf" --candump-log "$OUT/run.candump")
  if ! timeout 60 "$BIN/drive-io-interop" "${args[@]}" > "$OUT/drive-io-$sc.log" 2>&1; then
    FAIL=1
  fi
  grep '^INTEROP' "$OUT/drive-io-$sc.log" || { echo "INTEROP FAIL $sc: no result"; tail -5 "$OUT/drive-io-$sc.log"; FAIL=1; }
  kill "${PIDS[-1]}" 2>/dev/null || true
done

echo "-- (a2) vendor drives with CiA 404 load cells, identity checked"
VENDOR=(--eds config/eds/vendor-csp-drive.eds)
LOGSUFFIX=-vendor
for sc in run swapped; do
  port=$((PORT + n)); n=$((n + 1))
  extra=("${VENDOR[@]}" --cells)
  [ "$sc" = swapped ] && extra+=(--swap 2)
  drives "$sc" "$port" "${extra[@]}"
  args=(--transport "pycan-udp:$GROUP:$port" --scenario "$sc" --drives 2 "${VENDOR[@]}" --cells --vendor-identity)
  [ "$sc" = run ] && args+=(--dcf-dir "$OUT/dcf-vendor" --candump-log "$OUT/vendor-run.candump")
  if ! timeout 60 "$BIN/drive-io-interop" "${args[@]}" > "$OUT/drive-io-vendor-$sc.log" 2>&1; then
    FAIL=1
  fi
  grep '^INTEROP' "$OUT/drive-io-vendor-$sc.log" | sed -E 's/^INTEROP (PASS|FAIL) /INTEROP \1 vendor-/' \
    || { echo "INTEROP FAIL vendor-$sc: no result"; tail -5 "$OUT/drive-io-vendor-$sc.log"; FAIL=1; }
  kill "${PIDS[-1]}" 2>/dev/null || true
done

echo "-- (c) python canopen and Lely's dcfchk read drive-io's DCFs"
python3 tools/canopen_interop.py dcf --dcf-dir "$OUT/dcf" --drives 2 || FAIL=1
python3 tools/canopen_interop.py dcf --dcf-dir "$OUT/dcf-vendor" --drives 2 --vendor || FAIL=1
ndcf=0
for f in "$OUT"/dcf/*.dcf "$OUT"/dcf-vendor/*.dcf; do
  [ -e "$f" ] || continue
  node=$(basename "$f" .dcf); node=$((10#${node#node}))
  if dcfchk -n "$node" "$f" > "$OUT/dcfchk.log" 2>&1; then
    ndcf=$((ndcf + 1))
  else
    echo "  FAIL dcfchk $f:"; sed 's/^/    /' "$OUT/dcfchk.log"; FAIL=1
  fi
done
[ "$ndcf" -ge 6 ] && echo "  ok   dcfchk accepts all $ndcf DCFs" || { echo "  FAIL dcfchk: only $ndcf DCFs passed (want 6)"; FAIL=1; }

echo "-- (b) a python canopen master drives the winch emulator"
port=$((PORT + 10))
cat > "$OUT/emulator.toml" <<TOML
[bus]
transport = "pycan-udp:$GROUP:$port"
heartbeat_producer_ms = 20
heartbeat_timeout_ms = 300
$(for i in 1 2; do printf '[[winch]]\nnode_id = %d\ndrum_diameter_m = 0.305\ngear_ratio = 10.0\ncounts_per_rev = 1048576\nsign = 1\n' $i; done)
TOML
"$BIN/winch-emulator" --config "$OUT/emulator.toml" > "$OUT/emulator.log" 2>&1 &
PIDS+=($!)
sleep 1
timeout 90 python3 tools/canopen_interop.py master --group $GROUP --port "$port" --drives 2 \
  2> "$OUT/master.err" || { FAIL=1; tail -5 "$OUT/master.err"; }

[ "$FAIL" = 0 ] && echo "CANOPEN-INTEROP: PASS" || { echo "CANOPEN-INTEROP: FAIL (logs in $OUT)"; exit 1; }
