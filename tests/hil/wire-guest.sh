#!/bin/sh
# Runs inside the vcan guest (tools/wire-hil.sh): three more vcan interfaces, one per node of
# the hub's bus, then the forwarding checks (can-wire-hil starts can-wire itself).
for i in 10 11 12; do
  ip link add dev vcan$i type vcan && ip link set up vcan$i || { echo "WIRE_RESULT FAIL (vcan$i)"; exit 1; }
done
exec can-wire-hil
