#!/usr/bin/env bash
# Load figure for benches/RESULTS.md: motion-core's loop statistics from `crs sim`'s summary with
# the console off, and with the console on and 20 clients reading its live stream (each at the
# console's 25 Hz), alternating RUNS times. Prints a markdown table.
# Usage: tools/console-load.sh [RUNS]   (static release binaries as the HIL scripts build them)
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${1:-3}
BIN=${CONSOLE_BIN_DIR:-target/x86_64-unknown-linux-gnu/release}
OUT=out/console-load; mkdir -p "$OUT"
port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
clients() {  # $1 port, $2 seconds: 20 SSE clients, prints the slowest client's rate
  # The clients stand in for browsers on other machines: kept on CPU 0, off the motion CPU.
  taskset -c 0 python3 - "$1" "$2" <<'PY'
import socket, sys, threading, time
port, dur = int(sys.argv[1]), float(sys.argv[2])
counts = [0] * 20
spans = [1e-9] * 20
def client(k):
    for _ in range(200):
        try:
            s = socket.create_connection(("127.0.0.1", port), timeout=5); break
        except OSError:
            time.sleep(0.1)
    s.sendall(b"GET /api/events HTTP/1.1\r\nHost: x\r\n\r\n")
    t0 = time.time()
    # Until the console ends the stream (crs sim finished) or dur seconds.
    while time.time() - t0 < dur:
        try:
            d = s.recv(65536)
        except OSError:
            break
        if not d: break
        counts[k] += d.count(b"event: status")
        spans[k] = time.time() - t0
ts = [threading.Thread(target=client, args=(k,)) for k in range(20)]
[t.start() for t in ts]; [t.join() for t in ts]
rates = [c / s for c, s in zip(counts, spans)]
print(f"{min(rates):.1f} {sum(rates)/20:.1f}")
PY
}
echo "| run | console | clients | min / mean client rate (Hz) | cycles | overruns | lateness p99 (µs) | lateness max (µs) | compute p99 (µs) |"
echo "|---|---|---|---|---|---|---|---|---|"
for r in $(seq "$RUNS"); do
  for mode in off on; do
    args=(); rate="–"
    if [ $mode = on ]; then P=$(port); args=(--console "127.0.0.1:$P"); fi
    "$BIN/crs" sim --bin-dir "$BIN" --out "$OUT/$mode-$r" "${args[@]}" > "$OUT/$mode-$r.txt" 2>&1 &
    SIM=$!
    if [ $mode = on ]; then rate=$(clients "$P" 120 | tr ' ' '/'); fi
    wait $SIM || { echo "crs sim failed ($mode, run $r): $OUT/$mode-$r.txt" >&2; continue; }
    python3 - "$OUT/$mode-$r/summary.json" "$r" "$mode" "$rate" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
c = "20" if sys.argv[3] == "on" else "0"
print(f"| {sys.argv[2]} | {sys.argv[3]} | {c} | {sys.argv[4]} | {s['loop_cycles']} | {s['loop_overruns']} | {s['loop_lateness_p99_us']:.1f} | {s['loop_lateness_max_us']:.1f} | {s['loop_compute_p99_us']:.1f} |")
PY
  done
done
