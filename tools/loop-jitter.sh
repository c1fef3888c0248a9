#!/usr/bin/env bash
# Loop-timing bench: wake-up lateness of motion-core's 1 ms loop next to a bare
# clock_nanosleep(TIMER_ABSTIME) loop at the same settings, idle and with the other core loaded
# by stress-ng; cyclictest (Debian rt-tests) as a third, separate-process column. Writes a
# markdown table (and one JSON per scenario) to $OUT (default out/loop-jitter/).
#
#   tools/loop-jitter.sh                       # 20 s per scenario (10 s per loop), CI-sized
#   LOOP_JITTER_SECONDS=120 tools/loop-jitter.sh   # the figures in benches/RESULTS.md
#
# Settings (defaults: config/motion-core.toml's [realtime]): LOOP_CPU=1 (the loop), LOAD_CPU=0
# (stress-ng), PRIORITY=80 (SCHED_FIFO; 0 = SCHED_OTHER). Needs root (or CAP_SYS_NICE +
# LimitMEMLOCK) for SCHED_FIFO/mlockall; without it the run still happens, degraded, and the
# table says so. stress-ng and cyclictest are installed with apt-get when missing and root; the
# loaded scenario / cyclictest column is skipped (noted in the table) when they cannot be.
# Fails (exit 1) only when a measurement fails, never on the figures: timing on a shared VM is
# reported, not asserted (set MAX_P99_RATIO=x to fail when daemon p99 / bare p99 > x).
set -euo pipefail
cd "$(dirname "$0")/.."

SECS=${LOOP_JITTER_SECONDS:-20}
OUT=${OUT:-out/loop-jitter}
LOOP_CPU=${LOOP_CPU:-1}
LOAD_CPU=${LOAD_CPU:-0}
PRIORITY=${PRIORITY:-80}
PERIOD_US=1000
HALF=$(( (SECS + 1) / 2 ))
mkdir -p "$OUT"

if [ "$(nproc)" -lt 2 ]; then
  echo "loop-jitter: needs 2 CPUs (loop on $LOOP_CPU, load on $LOAD_CPU), found $(nproc)" >&2
  exit 1
fi

have_or_install() { # have_or_install COMMAND PACKAGE
  command -v "$1" >/dev/null && return 0
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "installing $2 (apt-get) for $1"
    apt-get install -y --no-install-recommends "$2" >/dev/null 2>&1 ||
      { apt-get update >/dev/null 2>&1 && apt-get install -y --no-install-recommends "$2" >/dev/null 2>&1; } || true
  fi
  command -v "$1" >/dev/null
}
have_stress=yes; have_or_install stress-ng stress-ng || have_stress=no
have_cyclic=yes; have_or_install cyclictest rt-tests || have_cyclic=no

echo "== building loop-jitter (release)"
cargo build --release -q -p loop-jitter --bin loop-jitter
BIN=${CARGO_TARGET_DIR:-target}/release/loop-jitter

# cyclictest -h prints one line per µs bucket ("000123 000045"), then "# Max Latencies: ...";
# bucket b holds latencies in [b, b+1) µs: quantiles are given as the bucket's upper edge.
cyclictest_row() { # cyclictest_row LABEL HISTFILE
  awk -v label="$1" '
    /^[0-9]+[ \t]+[0-9]+/ { b = $1 + 0; c = $2 + 0; cnt[b] = c; n += c; if (b > top) top = b; next }
    /# Histogram Overflows:/ { over = $4 + 0 }
    /# Max Latencies:/ { max = $4 + 0 }
    END {
      n += over
      if (n == 0) { printf "| %s | cyclictest (separate process, after) | 0 | - | - | - | - | failed |\n", label; exit }
      split("0.5 0.99 0.999", qs, " ")
      for (i = 1; i <= 3; i++) { t[i] = int(qs[i] * n); if (t[i] < qs[i] * n) t[i]++; if (t[i] < 1) t[i] = 1; v[i] = "> 20000" }
      acc = 0; k = 1
      for (b = 0; b <= top && k <= 3; b++) { acc += cnt[b]; while (k <= 3 && acc >= t[k]) { v[k] = sprintf("%d", b + 1); k++ } }
      printf "| %s | cyclictest (separate process, after) | %d | %s | %s | %s | %d | - |\n", label, n, v[1], v[2], v[3], max
    }' "$2"
}

run_scenario() { # run_scenario LABEL SLUG
  local label=$1 slug=$2
  echo "== scenario: $label ($SECS s: $HALF s daemon loop + $HALF s bare loop, then cyclictest $HALF s)"
  local args=(--seconds "$SECS" --cpu "$LOOP_CPU" --priority "$PRIORITY" --label "$label"
              --markdown --json "$OUT/$slug.json")
  [ -n "${MAX_P99_RATIO:-}" ] && args+=(--max-p99-ratio "$MAX_P99_RATIO")
  local rc=0
  "$BIN" "${args[@]}" >"$OUT/$slug.log" || rc=$?
  cat "$OUT/$slug.log"
  case $rc in
    0) ;;
    3) echo "loop-jitter: $label: p99 ratio above MAX_P99_RATIO=$MAX_P99_RATIO" >&2; ratio_fail=1 ;;
    *) echo "loop-jitter: $label: measurement failed (exit $rc)" >&2; exit 1 ;;
  esac
  grep '^| ' "$OUT/$slug.log" >>"$OUT/rows.md"
  grep -E '^(realtime |load average)' "$OUT/$slug.log" | sed "s/^/    [$label] /" >>"$OUT/applied.txt"
  if [ $have_cyclic = yes ]; then
    local policy=(--policy=fifo -p "$PRIORITY")
    [ "$PRIORITY" = 0 ] && policy=(--policy=other)
    # Same settings as the loop: one thread, CPU pinned, mlockall, absolute clock_nanosleep,
    # 1 ms; --default-system: no /dev/cpu_dma_latency tuning (the daemon does none either).
    if cyclictest -m "${policy[@]}" -a "$LOOP_CPU" -t 1 -i "$PERIOD_US" -D "${HALF}s" \
         -h 20000 -q --default-system >"$OUT/$slug.cyclictest.txt" 2>"$OUT/$slug.cyclictest.err"; then
      cyclictest_row "$label" "$OUT/$slug.cyclictest.txt" | tee -a "$OUT/rows.md"
    else
      echo "| $label | cyclictest | - | - | - | - | - | failed: $(head -c 120 "$OUT/$slug.cyclictest.err" | tr '\n|' '  ') |" >>"$OUT/rows.md"
    fi
  fi
}

: >"$OUT/rows.md"
: >"$OUT/applied.txt"
ratio_fail=0
stress_pid=""
cleanup() { [ -n "$stress_pid" ] && kill "$stress_pid" 2>/dev/null; wait 2>/dev/null || true; }
trap cleanup EXIT

run_scenario "idle" idle
if [ $have_stress = yes ]; then
  # CPU and memory stressors pinned to the other core (cache and memory-bus pressure reach the
  # loop's core too). Killed by its PID below.
  stress-ng --cpu 1 --vm 1 --vm-bytes 256M --taskset "$LOAD_CPU" --timeout $(( SECS + HALF + 60 ))s \
    >"$OUT/stress-ng.log" 2>&1 &
  stress_pid=$!
  sleep 2
  run_scenario "stress-ng --cpu 1 --vm 1 on cpu$LOAD_CPU" loaded
  kill "$stress_pid" 2>/dev/null || true
  wait "$stress_pid" 2>/dev/null || true
  stress_pid=""
else
  echo "| loaded | - | - | - | - | - | - | skipped: stress-ng not available |" >>"$OUT/rows.md"
fi

{
  echo "Loop wake-up lateness, 1 ms period, SCHED_FIFO $PRIORITY on CPU $LOOP_CPU (µs; ratio = motion-core loop / bare loop for p50 / p99 / p99.9 / max)."
  echo "$(date -u '+%Y-%m-%d %H:%M UTC'), $(uname -r), $(nproc) CPUs; command: \`LOOP_JITTER_SECONDS=$SECS tools/loop-jitter.sh\`"
  echo
  echo "| scenario | loop | samples | p50 | p99 | p99.9 | max | ratio to bare |"
  echo "|---|---|---|---|---|---|---|---|"
  cat "$OUT/rows.md"
  echo
  echo "Applied real-time settings and load averages (loop-jitter's report):"
  echo
  cat "$OUT/applied.txt"
  [ $have_cyclic = yes ] || echo "cyclictest: not available (rt-tests not installable): column skipped."
} >"$OUT/table.md"
echo
cat "$OUT/table.md"
[ $ratio_fail = 0 ]
