#!/bin/sh
# Runs inside the vcan guest (tools/stack-hil.sh): both cabins in one boot, each with the
# `emulated` timing profile (crs_supervisor::timing) and its inner tour, on the wire model over real
# vcan (`--transport vcan`: a vcan port per process and interface, can-wire forwarding).
rc=0
for p in icosahedron helicopter; do
  echo "== STACK-HIL platform $p"
  crs sim --platform "$p" --timing emulated --waypoints "tests/hil/waypoints-$p.csv" \
    --transport vcan --bin-dir /bin --out "/tmp/sim-$p" --check --timeout-s 400 || rc=1
done
exit $rc
