#!/usr/bin/env bash
# The project's test command (README "Run the tests"; .ci/run calls it).
# Format, lint, unit/integration/property tests on the host, then the HIL tests on real vcan
# inside a QEMU guest when the HIL harness is present.
#
# Every check is a SUITE: `suite NAME COMMAND [ARGS]` runs it (COMMAND may be a function of
# this file), `skip NAME REASON` records one that is not run and why. A failing suite does not
# stop the others; the last line counts the suites that passed, failed and were skipped, and
# the exit status is non-zero if any failed. Skipped suites are listed with their reasons: a
# run with skips is not a full pass and never says so.
set -euo pipefail
cd "$(dirname "$0")/.."

PASSED=()
FAILED=()
SKIPPED=()
T_START=$SECONDS

# Each suite's output is also kept in $SUITE_LOGS/N.log: the summary at the end repeats the
# failure lines of every failed suite (a CI log is often read from its tail only).
SUITE_LOGS=${SUITE_LOGS:-out/test-logs}
rm -rf "$SUITE_LOGS"
mkdir -p "$SUITE_LOGS"
FAILED_LOGS=()

# suite NAME COMMAND [ARGS...]: runs COMMAND with `set -e` in a subshell, records the result.
suite() {
  local name=$1 t0=$SECONDS rc log
  shift
  log="$SUITE_LOGS/$((${#PASSED[@]} + ${#FAILED[@]} + ${#SKIPPED[@]} + 1)).log"
  echo "== $name"
  set +e
  # tee in a process substitution, not a pipeline: a process a suite leaves behind holding its
  # stdout must not hang the run; tee gets up to 5 s to write the last lines out.
  local out tee_pid i
  exec {out}> >(tee "$log")
  tee_pid=$!
  (set -euo pipefail; "$@") >&"$out" 2>&1
  rc=$?
  exec {out}>&-
  for i in $(seq 50); do kill -0 "$tee_pid" 2>/dev/null || break; sleep 0.1; done
  set -e
  if [ "$rc" -eq 0 ]; then
    PASSED+=("$name")
    echo "-- $name: passed ($((SECONDS - t0)) s)"
  else
    FAILED+=("$name (exit $rc)")
    FAILED_LOGS+=("$log")
    echo "-- $name: FAILED (exit $rc, $((SECONDS - t0)) s)"
  fi
}

# The lines of a failed suite's log that say what failed (at most 25, the last ones).
failure_lines() {
  grep -aE 'FAIL|RETRY|panicked|^error(\[E[0-9]+\])?:|test result: FAILED|^---- ' "$1" | cut -c1-400 | tail -25 || true
}

# skip NAME REASON: a suite not run here, and why.
skip() {
  SKIPPED+=("$1: $2")
  echo "== $1: SKIPPED ($2)"
}

# --- the suites' commands (one function where a suite needs more than one command) ---

scipy_feasibility() {
  python3 -c "import numpy, scipy" 2>/dev/null || pip install -q numpy scipy >/dev/null 2>&1
  cargo build -q -p crs --bin crs
  python3 tools/feasibility_vs_scipy.py "${CARGO_TARGET_DIR:-target}/debug/crs" 40
}

scipy_calibration() {
  python3 -c "import numpy, scipy" 2>/dev/null || pip install -q numpy scipy >/dev/null 2>&1
  cargo build -q -p crs --bin crs
  python3 tools/calib_vs_scipy.py "${CARGO_TARGET_DIR:-target}/debug/crs"
}

# Doc tests whose `compile_fail,E…` must fail with that error code: stable rustdoc ignores the
# code, so rustdoc alone runs with its nightly switch (tools/rustdoc-error-codes.sh; rustc and
# the build cache are untouched).
workspace_tests() {
  RUSTDOC="$PWD/tools/rustdoc-error-codes.sh" cargo test --workspace --no-fail-fast
}

# --- the suites ---

suite "cargo fmt --check" cargo fmt --all -- --check
suite "cargo clippy (all targets, -D warnings)" cargo clippy --workspace --all-targets -- -D warnings
suite "cargo test (host; compile_fail doc tests with their error codes)" workspace_tests
# Unused dependencies: cargo-machete (a dependency no source file names fails the suite).
unused_dependencies() {
  command -v cargo-machete >/dev/null || cargo install -q cargo-machete --locked
  cargo machete
}
suite "no unused dependencies (cargo-machete)" unused_dependencies
suite "model analysis tools against scipy (HiGHS LP: exact wrench feasibility, eq. 3.29)" scipy_feasibility
suite "calibration against scipy least_squares on a data set of the independent benchmark plant" \
  scipy_calibration
suite "golden platform identity against its generator (python hashlib)" \
  python3 tools/identity_golden.py --check crates/crs-ipc/src/identity_golden.rs
suite "CANopen interop: drive-io vs python canopen drives, a python canopen master vs winch-emulator" \
  bash tools/canopen-interop.sh
suite "systemd units (systemd-analyze verify + the stack's unit policy)" bash tools/systemd-verify.sh

host_safety_matrix() {
  cargo build -q --workspace --bins
  # World-readable (mktemp -d is 0700): reset_from_foreign_process connects to the monitor's
  # reset socket as user nobody, whom the monitor itself must refuse (SO_PEERCRED), not the
  # directory's permissions.
  local w; w=$(mktemp -d); chmod 755 "$w"
  # Timing is asserted: what else ran on the host is part of the result. Stack processes left
  # by an earlier suite would compete with the matrix's real-time processes.
  local before left
  before=$(cut -d' ' -f1-3 /proc/loadavg)
  left=$(pgrep -a -f '(^|/)(motion-core|drive-io|safety-monitor|sim-plant|winch-emulator|can-wire)( |$)' || true)
  echo "host matrix: load average $before before the run; stack processes left running: ${left:-none}"
  local rc=0
  "${CARGO_TARGET_DIR:-target}/debug/safety-hil" --bin-dir "${CARGO_TARGET_DIR:-target}/debug" \
    --workdir "$w" --assert-timing --attempts 2 --retry-budget 2 || rc=$?
  if [ "$rc" -ne 0 ]; then
    echo "HOST MATRIX FAILED (exit $rc): load average $before before, $(cut -d' ' -f1-3 /proc/loadavg) after; stack processes left before it: ${left:-none}"
  fi
  return "$rc"
}
suite "safety monitor fault-injection matrix on the host at the spec's thresholds (wire model; timing asserted)" \
  host_safety_matrix

# One static release build serves all HIL suites (the emulated guest is slow; debug is
# slower).
export HIL_PROFILE=${HIL_PROFILE:-release}
HIL_SUITES=(
  "HIL: drive adapter on vcan (QEMU guest)|tools/hil-run.sh"
  "HIL: the full simulated stack on vcan (QEMU guest)|tools/stack-hil.sh"
  "HIL: the wire model's vcan forwarding (QEMU guest)|tools/wire-hil.sh"
)
# The guest matrix (behaviour only; the host suite above asserts timing). One run: a scenario
# whose stack the emulator stalled BEFORE its fault was injected runs once more, printed with the
# stall's cause, within a budget of 3 per run (tools/safety-hil.sh); a failure after the injection,
# or past the budget, fails the suite (docs/testing.md, "Retries": why the whole-matrix rerun
# after a failed run is gone).
if [ "${CRS_SKIP_HIL:-0}" = 1 ]; then
  skip "HIL: safety monitor fault-injection matrix on vcan (QEMU guest)" "CRS_SKIP_HIL=1"
else
  suite "HIL: safety monitor fault-injection matrix on vcan (QEMU guest)" bash tools/safety-hil.sh
fi
for s in "${HIL_SUITES[@]}"; do
  if [ "${CRS_SKIP_HIL:-0}" = 1 ]; then
    skip "${s%%|*}" "CRS_SKIP_HIL=1"
  else
    suite "${s%%|*}" bash "${s#*|}"
  fi
done

# The .deb under a real systemd in a Debian guest (tools/systemd-boot-test.sh: install,
# upgrade of the running stack, isolation, readiness, a ride, the monitor killed, a clean stop;
# docs/install.md, "The systemd boot test"). Root file system and kernel cached in $CRS_VCAN_CACHE.
# It passes since the monitor remembers its own frames for the longest reader stall its
# configuration allows (a guest stall had made it read its own echo as impersonation): 2026-11-27
# on a quiet host, 5 runs, 5 passed, 92-104 s warm, 126 s with a cold cache (rootfs and kernel
# built). On a host loaded by other builds the guest stalls 0.5-1.7 s and start-up can trip
# (docs/install.md, "Status"): CI must run on a quiet machine.
if [ "${CRS_SKIP_HIL:-0}" = 1 ]; then
  skip "HIL: the .deb under a real systemd (Debian guest)" "CRS_SKIP_HIL=1"
else
  suite "HIL: the .deb under a real systemd (Debian guest: install, upgrade, isolation, a ride, the monitor killed, a clean stop)" \
    bash tools/systemd-boot-test.sh
fi
suite "Debian package: layout, conffiles, man pages of every binary (tools/deb-test.sh)" bash tools/deb-test.sh

# The operator console in headless Chromium against a running `crs sim`, and the ecosystem's
# tools (can-utils, python-can, man, completions, install.sh) on what the stack writes. Both use
# the static release binaries the HIL scripts built (or build them the same way).
suite "operator console in headless Chromium (crs sim --console)" bash tools/console-test.sh
suite "ecosystem tools: candump log with can-utils and python-can, logs, plots, man pages, completions, install.sh" \
  bash tools/ecosystem-test.sh

echo
for i in "${!FAILED[@]}"; do
  echo "   FAILED: ${FAILED[$i]}; what it printed about it (${FAILED_LOGS[$i]}):"
  failure_lines "${FAILED_LOGS[$i]}" | sed 's/^/      | /'
done
for s in "${SKIPPED[@]}"; do echo "   SKIPPED: $s"; done
total=$((${#PASSED[@]} + ${#FAILED[@]} + ${#SKIPPED[@]}))
echo "== test.sh: ${#PASSED[@]} passed, ${#FAILED[@]} failed, ${#SKIPPED[@]} skipped of $total suites ($((SECONDS - T_START)) s)"
[ "${#FAILED[@]}" -eq 0 ]
